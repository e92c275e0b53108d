"""Launch one control scene on a ROS 2 install: sim_node, controller_node, recorder_node,
live_node.

    ros2 launch grazing_control grazing_control.launch.py                       # study scene
    ros2 launch grazing_control grazing_control.launch.py delta_d:=-9.0e-06 bag:=bags/scene2
    ros2 launch grazing_control grazing_control.launch.py live:=8765       # + live view
    ros2 launch grazing_control grazing_control.launch.py model:=config/models/two_mass_scene.yaml \
        controller_params:=gains.yaml                                          # n-DOF scene

Parameters come from the package's config/ (study.yaml, controller.yaml) unless other
files are given; ``delta_d`` and ``max_periods`` override the simulator's (write floats
with a decimal point, e.g. -9.0e-06). Every node's overrides come from
``grazing_control.ros.scene_nodes.scene_overrides``, the description ``grazing run``
uses too (one source: the design's actuation delay from ``controller_params``, the scene
token, the controller's model of the plant). With ``bag`` set, the recorder records the
scene there and the simulator waits until it has matched every topic
(``recorder/ready``). When the simulator exits after ``max_periods`` its scene's
controller, recorder and live view get SIGINT (the recorder closes its bag) and the
launch ends once nothing runs: included twice under two namespaces, each scene ends on its own. Any
node exiting with a nonzero status stops everything and the launch returns 1.
``/clock`` is remapped to ``clock`` (the namespace's own clock) and
``use_sim_time:=true`` puts the controller and recorder on it. ``live`` starts live_node
(docs/live.md) on that WebSocket port beside the scene, as ``grazing run --live PORT``;
the simulator does not wait for it. ``rig`` runs a simulated rig of a rig file in SI
at physical speed (issue 28; docs/rig_scene.md), as ``grazing run --rig FILE``: both
nodes read it and speak the driver contract, no controller file is used (the gains are
designed for the rig's budget) and the recorder also records the contract's topics.
``model`` runs an n-DOF scene of a model file (issue 17; docs/nodes.md, "n-DOF scenes"): both nodes read it, the
controller's parameter file must give its ``gains``, the simulator's file is used without
its 1-DOF model parameters, and ``delta_d`` left empty is the model file's (the study's
-5.0e-06 without a model). Machines without
``ros2 launch`` use ``grazing run`` (grazing_control.ros.launcher), the same scene with
plain processes.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import (DeclareLaunchArgument, EmitEvent, OpaqueFunction,
                            RegisterEventHandler)
from launch.event_handlers import OnProcessExit
from launch.events import matches_action
from launch.events.process import ShutdownProcess
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


#: /clock is absolute; remapped to the relative "clock", each scene (the include's
#: namespace) has its own simulated clock, so two namespaced scenes on one domain do not
#: share one (a controller on use_sim_time refused a genuine sample as "56.9 s old").
CLOCK = [("/clock", "clock")]


def generate_launch_description():
    share = get_package_share_directory("grazing_control")
    config = os.path.join(share, "config")
    args = [
        DeclareLaunchArgument("sim_params", default_value=os.path.join(config, "study.yaml"),
                              description="sim_node parameter file"),
        DeclareLaunchArgument("controller_params",
                              default_value=os.path.join(config, "controller.yaml"),
                              description="controller_node parameter file (grazing design --out)"),
        DeclareLaunchArgument("delta_d", default_value="",
                              description="wall clearance Delta d = d - d* ('' = -5.0e-06, "
                                          "or the model file's with model)"),
        DeclareLaunchArgument("model", default_value="",
                              description="n-DOF model file (docs/ndof_model.md); '' = "
                                          "controller_params' model_file if it has one "
                                          "(an n-DOF design), else the study's 1-DOF "
                                          "oscillator"),
        DeclareLaunchArgument("rig", default_value="",
                              description="rig file (docs/rig.md): a simulated rig in SI at "
                                          "physical speed, both nodes speaking the driver "
                                          "contract (docs/rig_scene.md), as grazing run "
                                          "--rig FILE; '' = the dimensionless scene"),
        DeclareLaunchArgument("max_periods", default_value="1200",
                              description="forcing periods of the scene"),
        DeclareLaunchArgument("enable_after", default_value="1000",
                              description="first controlled Pi2 sample"),
        DeclareLaunchArgument("bag", default_value="",
                              description="record to this bag directory ('' = no recording)"),
        DeclareLaunchArgument("live", default_value="",
                              description="start live_node (docs/live.md), a live view for "
                                          "Foxglove/Lichtblick, on this WebSocket port "
                                          "(0..65535, 0: any free port, logged); '' = none. "
                                          "As grazing run --live PORT"),
        DeclareLaunchArgument("use_sim_time", default_value="false",
                              description="controller and recorder on the simulator's clock "
                                          "(the scene's own: clock in its namespace)"),
    ]
    return LaunchDescription(args + [OpaqueFunction(function=_scene)])


def _scene(context):
    """The scene's nodes with the overrides of grazing_control.ros.scene_nodes (the ones
    `grazing run` gives them: one description, issue 19 §3), once the arguments are
    known; launch adds its own: the clock remapping, use_sim_time, the exit handlers."""
    from grazing_control.ros.scene_nodes import (NODES, design_model, scene_overrides,
                                                 sim_values_for_model, sim_values_for_rig)

    def arg(name):
        return LaunchConfiguration(name).perform(context)

    bag = arg("bag")
    rig = arg("rig") or None
    controller_params = arg("controller_params")
    if rig is not None:       # the rig file gives the gains' model; no controller file
        controller_params = {}
    model = arg("model") or design_model(controller_params)
    delta_d = float(arg("delta_d")) if arg("delta_d") else None if model or rig else -5.0e-06
    over = scene_overrides(controller_params, periods=int(arg("max_periods")),
                           delta_d=delta_d, enable_after=int(arg("enable_after")),
                           bag=bag or None, model=model, live=_port(arg("live")), rig=rig)
    sim_time = arg("use_sim_time").lower() in ("true", "1", "yes")
    files = {"sim_node": [arg("sim_params")], "controller_node": [controller_params],
             "recorder_node": [], "live_node": []}
    if model is not None:     # the simulator file's scene settings, not its 1-DOF model
        files["sim_node"] = [sim_values_for_model(arg("sim_params"))]
    if rig is not None:       # ... nor what the rig file sets (its model, sensor, pace)
        files["sim_node"] = [sim_values_for_rig(arg("sim_params"))]
        files["controller_node"] = []
    nodes = {}
    for name in NODES:
        if over[name] is None:
            continue
        params = dict(over[name])
        if name != "sim_node":
            params["use_sim_time"] = sim_time
        nodes[name] = Node(package="grazing_control", executable=name, name=name,
                           output="screen", remappings=CLOCK,
                           parameters=files[name] + [params])
    ended = _on_exit([nodes[n] for n in nodes if n != "sim_node"])
    return list(nodes.values()) + [
        RegisterEventHandler(OnProcessExit(target_action=node, on_exit=ended))
        for node in nodes.values()]


def _port(text):
    """The ``live`` argument: None for '', else a port 0..65535 (ValueError naming it)."""
    if not text:
        return None
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise ValueError(f"live:={text} is invalid: valid range is a port 0..65535 "
                         "(0: any free port) or '' for no live view")
    return port


class NodeFailed(RuntimeError):
    """A node of the scene exited with a nonzero status: the launch ends with status 1."""


def _on_exit(scene):
    """The handler of a node's exit in a scene of ``scene`` (the controller and recorder
    actions): the simulator with status 0 ends *this* scene (SIGINT to its controller and
    recorder; the launch ends when nothing runs any more, so a second scene included
    under another namespace goes on); any node with another status, unless the launch
    is already shutting down, raises NodeFailed: launch catches it, shuts everything down
    and returns 1 (LaunchService.run_async), so a refused controller or recorder no
    longer leaves the simulator running with status 0 (issue 19 §3)."""
    def ended(event, context):
        if context.is_shutdown:
            return None
        name = event.process_name              # e.g. "sim_node-3"
        if event.returncode != 0:
            raise NodeFailed(f"{name} exited with status {event.returncode}: the scene is "
                             "stopped")
        if name.startswith("sim_node"):
            return [EmitEvent(event=ShutdownProcess(process_matcher=matches_action(node)))
                    for node in scene]
        return None
    return ended

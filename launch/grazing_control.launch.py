"""Launch one control scene on a ROS 2 install: sim_node, controller_node, recorder_node.

    ros2 launch grazing_control grazing_control.launch.py                       # study scene
    ros2 launch grazing_control grazing_control.launch.py delta_d:=-9.0e-06 bag:=bags/scene2

Parameters come from the package's config/ (study.yaml, controller.yaml) unless other
files are given; ``delta_d`` and ``max_periods`` override the simulator's (write floats
with a decimal point, e.g. -9.0e-06). With ``bag`` set, the recorder records the scene
there and the simulator waits until it has matched every topic (``recorder/ready``)
before starting; the bag path is compared as text (NotEqualsSubstitution, launch >= 3.1,
Jazzy), never evaluated, so any path works. When the simulator exits after
``max_periods`` its scene's controller and recorder get SIGINT (the recorder closes its
bag) and the launch ends once nothing runs: included twice under two namespaces, each
scene ends on its own. Any node exiting with a nonzero status stops everything and the
launch returns 1. ``/clock`` is remapped to ``clock`` (the namespace's own clock) and
``use_sim_time:=true`` puts the controller and recorder on it. The simulator applies the actuation delay the controller's gains
were designed for (``actuation_delay`` of ``controller_params``, as ``grazing run``
does; a simulator started with another delay refuses to start, naming both). Machines
without ``ros2 launch`` use ``grazing run`` (grazing_control.ros.launcher), which does
the same with plain processes.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import (DeclareLaunchArgument, EmitEvent, OpaqueFunction,
                            RegisterEventHandler)
from launch.conditions import IfCondition
from launch.event_handlers import OnProcessExit
from launch.events import matches_action
from launch.events.process import ShutdownProcess
from launch.substitutions import IfElseSubstitution, LaunchConfiguration, NotEqualsSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


#: /clock is absolute; remapped to the relative "clock", each scene (the include's
#: namespace) has its own simulated clock, so two namespaced scenes on one domain do not
#: share one (a controller on use_sim_time refused a genuine sample as "56.9 s old").
CLOCK = [("/clock", "clock")]


def generate_launch_description():
    share = get_package_share_directory("grazing_control")
    config = os.path.join(share, "config")
    bag = LaunchConfiguration("bag")
    # compared as text, never evaluated: any bag path works (quotes included)
    recording = NotEqualsSubstitution(bag, "")

    args = [
        DeclareLaunchArgument("sim_params", default_value=os.path.join(config, "study.yaml"),
                              description="sim_node parameter file"),
        DeclareLaunchArgument("controller_params",
                              default_value=os.path.join(config, "controller.yaml"),
                              description="controller_node parameter file (grazing design --out)"),
        DeclareLaunchArgument("delta_d", default_value="-5.0e-06",
                              description="wall clearance Delta d = d - d*"),
        DeclareLaunchArgument("max_periods", default_value="1200",
                              description="forcing periods of the scene"),
        DeclareLaunchArgument("enable_after", default_value="1000",
                              description="first controlled Pi2 sample"),
        DeclareLaunchArgument("bag", default_value="",
                              description="record to this bag directory ('' = no recording)"),
        DeclareLaunchArgument("use_sim_time", default_value="false",
                              description="controller and recorder on the simulator's clock "
                                          "(the scene's own: clock in its namespace)"),
    ]
    sim_time = ParameterValue(LaunchConfiguration("use_sim_time"), value_type=bool)

    controller = Node(
        package="grazing_control", executable="controller_node", name="controller_node",
        output="screen", remappings=CLOCK, parameters=[LaunchConfiguration("controller_params"), {
            "enable_after": LaunchConfiguration("enable_after"), "use_sim_time": sim_time}])
    recorder = Node(
        package="grazing_control", executable="recorder_node", name="recorder_node",
        output="screen", condition=IfCondition(recording), remappings=CLOCK,
        parameters=[{"output": ParameterValue(bag, value_type=str),
                     "require_complete": True, "use_sim_time": sim_time}])
    ended = _on_exit((controller, recorder))
    def simulator(context):
        """sim_node with the design's actuation delay read from controller_params (the
        file is known only once the arguments are), and the scene's end with it."""
        from grazing_control.ros.launcher import design_delay

        overrides = {
            "delta_d": LaunchConfiguration("delta_d"),
            "max_periods": LaunchConfiguration("max_periods"),
            "exit_when_done": True,
            "wait_for_subscribers": IfElseSubstitution(recording, "1", "0"),
            "wait_for_recorder": IfElseSubstitution(recording, "true", "false"),
        }
        delay = design_delay(LaunchConfiguration("controller_params").perform(context))
        if delay is not None:
            overrides["actuation_delay"] = delay
        sim = Node(
            package="grazing_control", executable="sim_node", name="sim_node", output="screen",
            remappings=CLOCK, parameters=[LaunchConfiguration("sim_params"), overrides])
        return [sim, RegisterEventHandler(OnProcessExit(target_action=sim, on_exit=ended))]

    watch = [RegisterEventHandler(OnProcessExit(target_action=node, on_exit=ended))
             for node in (controller, recorder)]
    return LaunchDescription(args + [recorder, controller, OpaqueFunction(function=simulator)]
                             + watch)


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

"""Launch ``stiffness_bridge`` on a stock ROS 2 Jazzy machine (docs/controllers.md):

    ros2 launch tensegrity_stiffness stiffness_bridge.launch.py preset:=admittance \\
        input_topic:=/j1/stiffness_node/cartesian_stiffness target_node:=/admittance_controller

Arguments: ``preset`` (crisp, crisp_full, column_major_36, cartesian_controllers, admittance,
crisp_parameters), ``namespace``, ``input_topic`` (remaps ``~/input_stiffness``), ``output_topic``
(remaps ``~/output_stiffness`` of topic presets, e.g. the controller's ``target_stiffness``),
``target_node`` (the controller node of parameter presets) and ``params_file`` (a ROS parameter
file with the bridge's other parameters: output.pose, clamps, time constant...; empty: none); any
parameter of the bridge's table (docs/parameters.md) or ``use_sim_time`` given as ``name:=value``
is set after them, typed by the table (:mod:`tensegrity_stiffness.ros.launch_parameters`). The
per-preset files ``stiffness_bridge_<preset>.launch.py`` include this one with their preset.
``launch`` is not on PyPI, so the test suite only checks that these files compile and name the
installed executable and presets.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch_ros.actions import Node

from tensegrity_stiffness.ros.launch_parameters import single_parameters

PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'stiffness_bridge'
ARGUMENTS = {
    'preset': ('crisp', 'the controller form (docs/controllers.md)'),
    'namespace': ('', 'namespace of the bridge'),
    'input_topic': ('', 'K_c source: a stiffness_node ~/cartesian_stiffness or a spine_node '
                        '~/tip_stiffness (empty: ~/input_stiffness)'),
    'output_topic': ('', "topic presets: the controller's stiffness topic (empty: "
                         '~/output_stiffness)'),
    'target_node': ('', 'parameter presets: full name of the controller node'),
    'params_file': ('', "ROS parameter file of the bridge's other parameters (empty: none)"),
}


def _bridge(context, *args, **kwargs) -> list:
    value = {name: context.launch_configurations.get(name, default)
             for name, (default, _) in ARGUMENTS.items()}
    parameters: list = [{'preset': value['preset'], 'target.node': value['target_node']}]
    if value['params_file']:
        parameters.append(value['params_file'])
    given = single_parameters(EXECUTABLE, context.launch_configurations)
    if given:
        parameters.append(given)
    remappings = [(topic, value[arg]) for topic, arg in (('~/input_stiffness', 'input_topic'),
                                                          ('~/output_stiffness', 'output_topic'))
                  if value[arg]]
    return [Node(package=PACKAGE, executable=EXECUTABLE, name=EXECUTABLE,
                 namespace=value['namespace'], parameters=parameters, remappings=remappings,
                 output='screen', emulate_tty=True)]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=description)
         for name, (default, description) in ARGUMENTS.items()]
        + [OpaqueFunction(function=_bridge)])

"""Launch the twin of the joint: ``sim_node`` (MuJoCo) wired to ``stiffness_node``:

    ros2 launch tensegrity_stiffness twin.launch.py namespace:=/twin \\
        params_file:=/path/to/config.yaml swing_amplitude:=0.1 sim.rate:=100.0

The twin publishes the truth on ``sim_node/pose``, which is remapped onto the input
``~/pose`` of ``stiffness_node``, so the whole loop runs without hardware; both read the same
``params_file`` (default: the installed ``config/default_joint.yaml``). ``swing_amplitude`` (N,
default 0.1; 0: still) and ``swing_period`` (s, default 10) make the twin swing a load. Any
parameter of either node's table (docs/parameters.md) or ``use_sim_time`` given as
``name:=value`` is set on each node that has it, after the file, typed by the table
(:mod:`tensegrity_stiffness.ros.launch_parameters`).
``twin_spine.launch.py`` is the same for the spine (:data:`TWINS`, :func:`twin_description`).
``launch`` is not on PyPI: ``bash scripts/run_twin.sh`` starts the same pair (and prints a
live summary); the test suite checks that this file compiles, names the installed executables
and config and sets only the nodes' parameters.
"""

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.parameter_descriptions import ParameterValue

from tensegrity_stiffness.ros.launch_parameters import launch_node

PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'sim_node'
#: Per twin: the partner node, its packaged config, the partner's input that the twin's truth
#: feeds (relative: both nodes share the namespace) and the default swing amplitude (N).
TWINS = {
    'joint': ('stiffness_node', 'default_joint.yaml', ('~/pose', 'sim_node/pose'), '0.1'),
    'spine': ('spine_node', 'default_spine.yaml', ('~/poses', 'sim_node/poses'), '0.01'),
}


def twin_description(kind: str) -> LaunchDescription:
    """The twin of ``kind`` (``'joint'`` or ``'spine'``) and its partner node."""
    partner, config, remapping, swing = TWINS[kind]
    default_params = str(Path(get_package_share_directory(PACKAGE)) / 'config' / config)
    namespace = LaunchConfiguration('namespace')
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='twin',
                              description='namespace of both nodes'),
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='ROS parameter file of the model (config/*.yaml); '
                              'single parameters: <name>:=<value>'),
        DeclareLaunchArgument('swing_amplitude', default_value=swing,
                              description='force of the swinging load, N (0: still)'),
        DeclareLaunchArgument('swing_period', default_value='10.0',
                              description='period of the swinging load, s'),
        launch_node(EXECUTABLE, fixed=[{
            'sim.spine': kind == 'spine',
            'load.swing_amplitude': ParameterValue(
                LaunchConfiguration('swing_amplitude'), value_type=float),
            'load.swing_period': ParameterValue(
                LaunchConfiguration('swing_period'), value_type=float)}], namespace=namespace),
        launch_node(partner, remappings=[remapping], namespace=namespace),
    ])


def generate_launch_description() -> LaunchDescription:
    return twin_description('joint')

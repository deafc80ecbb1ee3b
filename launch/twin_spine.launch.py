"""Launch the twin of the spine: ``sim_node`` (``sim.spine``) wired to ``spine_node``:

    ros2 launch tensegrity_stiffness twin_spine.launch.py namespace:=/twin \\
        params_file:=/path/to/config.yaml swing_amplitude:=0.01

The twin publishes the truth on ``sim_node/poses``, which is remapped onto the input
``~/poses`` of ``spine_node``, so the whole loop runs without hardware; both read the same
``params_file`` (default: the installed ``config/default_spine.yaml``). ``swing_amplitude`` (N,
default 0.01; 0: still) and ``swing_period`` (s, default 10) make the twin swing a load.
``launch`` is not on PyPI: ``bash scripts/run_twin.sh`` starts the same pair (and prints a
live summary); the test suite checks that this file compiles and names the installed
executables and config.
"""

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'sim_node'
PARTNER = 'spine_node'
CONFIG = 'default_spine.yaml'
#: The partner's input that the twin's truth feeds (relative: both nodes share the namespace).
REMAPPING = ('~/poses', 'sim_node/poses')


def generate_launch_description() -> LaunchDescription:
    default_params = str(Path(get_package_share_directory(PACKAGE)) / 'config' / CONFIG)
    params = LaunchConfiguration('params_file')
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='twin',
                              description='namespace of both nodes'),
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='ROS parameter file of the model (config/*.yaml)'),
        DeclareLaunchArgument('swing_amplitude', default_value='0.01',
                              description='force of the swinging load, N (0: still)'),
        DeclareLaunchArgument('swing_period', default_value='10.0',
                              description='period of the swinging load, s'),
        Node(package=PACKAGE, executable=EXECUTABLE, name=EXECUTABLE,
             namespace=LaunchConfiguration('namespace'),
             parameters=[params, {
                 'sim.spine': True,
                 'load.swing_amplitude': ParameterValue(
                     LaunchConfiguration('swing_amplitude'), value_type=float),
                 'load.swing_period': ParameterValue(
                     LaunchConfiguration('swing_period'), value_type=float)}],
             output='screen', emulate_tty=True),
        Node(package=PACKAGE, executable=PARTNER, name=PARTNER,
             namespace=LaunchConfiguration('namespace'), parameters=[params],
             remappings=[REMAPPING], output='screen', emulate_tty=True),
    ])

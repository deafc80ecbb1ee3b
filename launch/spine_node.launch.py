"""Launch ``spine_node`` (a whole spine) on a stock ROS 2 Jazzy machine:

    ros2 launch tensegrity_stiffness spine_node.launch.py namespace:=/robot \\
        params_file:=/path/to/spine.yaml equilibrium.max_iterations:=100

``namespace`` (default: none) and ``params_file`` (default: the installed
``config/default_spine.yaml``; empty: none) are launch arguments; any parameter of the node's
table (docs/parameters.md) or ``use_sim_time`` given as ``name:=value`` is set after the file,
typed by the table (:mod:`tensegrity_stiffness.ros.launch_parameters`). ``launch`` is not on
PyPI, so the test suite only checks that this file compiles, names the installed executable and
config, and sets only the node's parameters.
"""

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration

from tensegrity_stiffness.ros.launch_parameters import launch_node

PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'spine_node'
CONFIG = 'default_spine.yaml'


def generate_launch_description() -> LaunchDescription:
    default_params = str(Path(get_package_share_directory(PACKAGE)) / 'config' / CONFIG)
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of the node (its topics are ~/...)'),
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='ROS parameter file of the spine (config/*.yaml); '
                              'single parameters: <name>:=<value>'),
        launch_node(EXECUTABLE, namespace=LaunchConfiguration('namespace')),
    ])

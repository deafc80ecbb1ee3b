"""Launch ``stiffness_node`` on a stock ROS 2 Jazzy machine:

    ros2 launch tensegrity_stiffness stiffness_node.launch.py namespace:=/spine/j1 \\
        params_file:=/path/to/joint.yaml

``namespace`` (default: none) and ``params_file`` (default: the installed
``config/default_joint.yaml``) are launch arguments. ``launch`` is not on PyPI, so the test suite
only checks that this file compiles and names the installed executable and config.
"""

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'stiffness_node'
CONFIG = 'default_joint.yaml'


def generate_launch_description() -> LaunchDescription:
    default_params = str(Path(get_package_share_directory(PACKAGE)) / 'config' / CONFIG)
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of the node (its topics are ~/...)'),
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='ROS parameter file of the joint (config/*.yaml)'),
        Node(package=PACKAGE, executable=EXECUTABLE, name=EXECUTABLE,
             namespace=LaunchConfiguration('namespace'),
             parameters=[LaunchConfiguration('params_file')], output='screen',
             emulate_tty=True),
    ])

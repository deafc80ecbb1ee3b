"""Launch ``structure_node`` (a structure of rigid bodies and strings) on a stock ROS 2 Jazzy
machine:

    ros2 launch tensegrity_stiffness structure_node.launch.py namespace:=/robot \\
        structure:=three_bar.yaml params_file:=/path/to/params.yaml tf.enabled:=false

``namespace`` (default: none), ``structure`` (the ``structure.config`` parameter: a path, or a
packaged example of config/examples; default the installed ``config/examples/six_bar.yaml``) and
``params_file`` (a ROS parameter file of the node's other parameters; default none) are launch
arguments; any parameter of the node's table (docs/parameters.md) or ``use_sim_time`` given as
``name:=value`` is set after them, typed by the table
(:mod:`tensegrity_stiffness.ros.launch_parameters`). ``launch`` is not on PyPI, so the test suite
only checks that this file compiles, names the installed executable and sets only the node's
parameters.
"""

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration

from tensegrity_stiffness.ros.launch_parameters import launch_node

PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'structure_node'
CONFIG = 'examples/six_bar.yaml'


def generate_launch_description() -> LaunchDescription:
    default_structure = str(Path(get_package_share_directory(PACKAGE)) / 'config' / CONFIG)
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of the node (its topics are ~/...)'),
        DeclareLaunchArgument('structure', default_value=default_structure,
                              description='the structure file, or a packaged example'),
        DeclareLaunchArgument('params_file', default_value='',
                              description="ROS parameter file of the node's other parameters; "
                              'single parameters: <name>:=<value>'),
        launch_node(EXECUTABLE, fixed=[{'structure.config': LaunchConfiguration('structure')}],
                    namespace=LaunchConfiguration('namespace')),
    ])

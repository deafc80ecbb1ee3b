"""Launch ``structure_node`` (a structure of rigid bodies and strings) on a stock ROS 2 Jazzy
machine:

    ros2 launch tensegrity_stiffness structure_node.launch.py namespace:=/robot \\
        structure:=three_bar.yaml params_file:=/path/to/params.yaml

``namespace`` (default: none), ``structure`` (the ``structure.config`` parameter: a path, or a
packaged example of config/examples; default the installed
``config/examples/six_bar.yaml``) and ``params_file`` (a ROS
parameter file of the node's other parameters; default none) are launch arguments. ``launch`` is
not on PyPI, so the test suite only checks that this file compiles and names the installed
executable.
"""

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node

PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'structure_node'
CONFIG = 'examples/six_bar.yaml'


def generate_launch_description() -> LaunchDescription:
    default_structure = str(Path(get_package_share_directory(PACKAGE)) / 'config' / CONFIG)
    structure = {'structure.config': LaunchConfiguration('structure')}
    has_params = PythonExpression(["'", LaunchConfiguration('params_file'), "' != ''"])

    def node(parameters: list, condition: object) -> Node:
        return Node(package=PACKAGE, executable=EXECUTABLE, name=EXECUTABLE,
                    namespace=LaunchConfiguration('namespace'), parameters=parameters,
                    output='screen', emulate_tty=True, condition=condition)

    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of the node (its topics are ~/...)'),
        DeclareLaunchArgument('structure', default_value=default_structure,
                              description='the structure file, or a packaged example'),
        DeclareLaunchArgument('params_file', default_value='',
                              description="ROS parameter file of the node's other parameters"),
        node([LaunchConfiguration('params_file'), structure], IfCondition(has_params)),
        node([structure], UnlessCondition(has_params)),
    ])

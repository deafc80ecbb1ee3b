"""Launch ``structure_estimator_node`` on the twin of a structure (``structure_sim_node``), wired
as ``bash scripts/run_twin.sh --structure ... --estimate`` wires them:

    ros2 launch tensegrity_stiffness structure_estimator.launch.py namespace:=/twin \\
        structure:=three_bar.yaml params_file:=/path/to/estimator_params.yaml

The estimator's inputs ``~/measured_lengths``, ``~/measured_rest_lengths``,
``~/measured_contacts``, ``~/measured_markers`` and ``~/imu/<bar>`` (every bar of the
structure) are remapped onto the twin's outputs; both nodes take ``structure.config``
(``structure``: a packaged example of config/examples or a path; default the installed
``config/examples/six_bar.yaml``) and their rest-length commands from ``<namespace>/rest_lengths``.
``params_file`` (default none) holds the estimator's other parameters (docs/structures.md, "The
estimator node"). On a robot, drop the twin and remap the inputs onto its drivers' topics.
``launch`` is not on PyPI: the test suite checks that this file compiles and names the installed
executable and config.
"""

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'structure_estimator_node'
TWIN = 'structure_sim_node'
CONFIG = 'examples/six_bar.yaml'
#: The estimator's array inputs, each the twin's output of the same name.
ARRAY_INPUTS = ('measured_lengths', 'measured_rest_lengths', 'measured_contacts',
                'measured_markers')


def _nodes(context: object) -> list[Node]:
    from tensegrity_stiffness.nodes.structure_node import structure_path
    from tensegrity_stiffness.structures.structure import Structure

    structure = LaunchConfiguration('structure').perform(context)
    params_file = LaunchConfiguration('params_file').perform(context)
    namespace = LaunchConfiguration('namespace')
    bars = Structure.from_yaml(structure_path(structure)).bar_names
    inputs = [*ARRAY_INPUTS, *(f'imu/{bar}' for bar in bars)]
    source = {'structure.config': structure}
    return [
        Node(package=PACKAGE, executable=TWIN, name=TWIN, namespace=namespace,
             parameters=[source], remappings=[('~/rest_lengths', 'rest_lengths')],
             output='screen', emulate_tty=True),
        Node(package=PACKAGE, executable=EXECUTABLE, name=EXECUTABLE, namespace=namespace,
             parameters=[*([params_file] if params_file else []), source],
             remappings=[*((f'~/{name}', f'{TWIN}/{name}') for name in inputs),
                         ('~/rest_lengths', 'rest_lengths')],
             output='screen', emulate_tty=True),
    ]


def generate_launch_description() -> LaunchDescription:
    default_structure = str(Path(get_package_share_directory(PACKAGE)) / 'config' / CONFIG)
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='twin',
                              description='namespace of both nodes'),
        DeclareLaunchArgument('structure', default_value=default_structure,
                              description='the structure file, or a packaged example'),
        DeclareLaunchArgument('params_file', default_value='',
                              description="ROS parameter file of the estimator's parameters"),
        OpaqueFunction(function=_nodes),
    ])

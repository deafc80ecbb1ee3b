"""Launch ``structure_estimator_node`` on the twin of a structure (``structure_sim_node``), wired
as ``bash scripts/run_twin.sh --structure ... --estimate`` wires them:

    ros2 launch tensegrity_stiffness structure_estimator.launch.py namespace:=/twin \\
        structure:=three_bar.yaml params_file:=/path/to/estimator_params.yaml

The estimator's inputs ``~/measured_lengths``, ``~/measured_rest_lengths``,
``~/measured_contacts``, ``~/measured_markers`` and ``~/imu/<bar>`` (every bar of the
structure) are remapped onto the twin's outputs; both nodes take ``structure.config``
(``structure``: a packaged example of config/examples or a path; default ``six_bar.yaml``)
and their rest-length commands from ``<namespace>/rest_lengths``. ``params_file`` (default
none) is a ROS parameter file for both (the estimator's parameters: docs/structures.md, "The
estimator node"); any parameter of either node's table given as ``name:=value`` is set on each
node that has it, after the file (:mod:`tensegrity_stiffness.ros.launch_parameters`). On a
robot, drop the twin and remap the inputs onto its drivers' topics.
``launch`` is not on PyPI: the test suite checks that this file compiles and names the installed
executable and config.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration

from tensegrity_stiffness.ros.launch_parameters import launch_node

PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'structure_estimator_node'
TWIN = 'structure_sim_node'
CONFIG = 'examples/six_bar.yaml'
STRUCTURE = 'six_bar.yaml'
#: The estimator's array inputs, each the twin's output of the same name.
ARRAY_INPUTS = ('measured_lengths', 'measured_rest_lengths', 'measured_contacts',
                'measured_markers')


def estimator_remappings(context: object) -> list[tuple[str, str]]:
    """The estimator's inputs onto the twin's outputs: the arrays and one IMU per bar of the
    launched structure."""
    from tensegrity_stiffness.nodes.structure_node import structure_path
    from tensegrity_stiffness.structures.structure import Structure

    structure = LaunchConfiguration('structure').perform(context)
    bars = Structure.from_yaml(structure_path(structure)).bar_names
    inputs = [*ARRAY_INPUTS, *(f'imu/{bar}' for bar in bars)]
    return [*((f'~/{name}', f'{TWIN}/{name}') for name in inputs),
            ('~/rest_lengths', 'rest_lengths')]


def generate_launch_description() -> LaunchDescription:
    structure = LaunchConfiguration('structure')
    namespace = LaunchConfiguration('namespace')
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='twin',
                              description='namespace of both nodes'),
        DeclareLaunchArgument('structure', default_value=STRUCTURE,
                              description='the structure file, or a packaged example'),
        DeclareLaunchArgument('params_file', default_value='',
                              description='ROS parameter file of both nodes (empty: none); '
                              'single parameters: <name>:=<value>'),
        launch_node(TWIN, fixed=[{'structure.config': structure}],
                    remappings=[('~/rest_lengths', 'rest_lengths')], namespace=namespace),
        launch_node(EXECUTABLE, fixed=[{'structure.config': structure}],
                    remappings=estimator_remappings, namespace=namespace),
    ])

"""Launch the twin of a structure: ``structure_sim_node`` (MuJoCo, from branch h-structtwin)
wired to ``structure_node``:

    ros2 launch tensegrity_stiffness structure_twin.launch.py namespace:=/twin \\
        structure:=six_bar.yaml

The twin publishes the bodies' true poses on ``structure_sim_node/poses``, which is remapped
onto the input ``~/poses`` of ``structure_node``; both nodes take their rest lengths from the one
topic ``<namespace>/rest_lengths`` (the twin as motor commands at its rate limit, the node as
the rest lengths it evaluates with), so a command published there (latched) drives both.
``structure`` is a packaged example of config/examples (default ``six_bar.yaml``): both nodes'
``structure.config``. ``params_file`` (default none) is a
ROS parameter file for both; any parameter of either node's table (docs/parameters.md) or
``use_sim_time`` given as ``name:=value`` is set on each node that has it, after the file, typed
by the table (:mod:`tensegrity_stiffness.ros.launch_parameters`). ``launch`` is not on PyPI: the
test suite checks that this file compiles, names the installed executables and config and sets
only the nodes' parameters.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration

from tensegrity_stiffness.ros.launch_parameters import launch_node

PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'structure_sim_node'
PARTNER = 'structure_node'
CONFIG = 'examples/six_bar.yaml'
STRUCTURE = 'six_bar.yaml'


def generate_launch_description() -> LaunchDescription:
    structure = LaunchConfiguration('structure')
    namespace = LaunchConfiguration('namespace')
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='twin',
                              description='namespace of both nodes'),
        DeclareLaunchArgument('structure', default_value=STRUCTURE,
                              description='a packaged example of config/examples'),
        DeclareLaunchArgument('params_file', default_value='',
                              description='ROS parameter file of both nodes (empty: none); '
                              'single parameters: <name>:=<value>'),
        launch_node(EXECUTABLE, fixed=[{'structure.config': structure}],
                    remappings=[('~/rest_lengths', 'rest_lengths')], namespace=namespace),
        launch_node(PARTNER, fixed=[{'structure.config': structure}],
                    remappings=[('~/poses', f'{EXECUTABLE}/poses'),
                                ('~/rest_lengths', 'rest_lengths')], namespace=namespace),
    ])

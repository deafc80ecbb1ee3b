"""Launch the twin of a structure: ``structure_sim_node`` (MuJoCo, from branch h-structtwin)
wired to ``structure_node``:

    ros2 launch tensegrity_stiffness structure_twin.launch.py namespace:=/twin \\
        structure:=six_bar.yaml

The twin publishes the bodies' true poses on ``structure_sim_node/poses``, which is remapped
onto the input ``~/poses`` of ``structure_node``; both nodes take their rest lengths from the one
topic ``<namespace>/rest_lengths`` (the twin as motor commands at its rate limit, the node as
the rest lengths it evaluates with), so a command published there (latched) drives both.
``structure`` is a packaged example of config/examples (default ``six_bar.yaml``): both nodes'
``structure.config``. ``launch`` is not on PyPI: the test
suite checks that this file compiles and names the installed executables and config.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

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
        Node(package=PACKAGE, executable=EXECUTABLE, name=EXECUTABLE, namespace=namespace,
             parameters=[{'structure.config': structure}],
             remappings=[('~/rest_lengths', 'rest_lengths')],
             output='screen', emulate_tty=True),
        Node(package=PACKAGE, executable=PARTNER, name=PARTNER, namespace=namespace,
             parameters=[{'structure.config': structure}],
             remappings=[('~/poses', f'{EXECUTABLE}/poses'),
                         ('~/rest_lengths', 'rest_lengths')],
             output='screen', emulate_tty=True),
    ])

"""Launch ``stiffness_bridge`` with preset ``cartesian_controllers`` (docs/controllers.md):
includes ``stiffness_bridge.launch.py`` with ``preset:=cartesian_controllers``;
the other arguments pass through:

    ros2 launch tensegrity_stiffness stiffness_bridge_cartesian_controllers.launch.py \\
        input_topic:=/j1/stiffness_node/cartesian_stiffness \\
        target_node:=/my_controller params_file:=bridge.yaml
"""

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import IncludeLaunchDescription
from launch.launch_description_sources import PythonLaunchDescriptionSource

PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'stiffness_bridge'
PRESET = 'cartesian_controllers'
INCLUDED = 'stiffness_bridge.launch.py'


def generate_launch_description() -> LaunchDescription:
    path = Path(get_package_share_directory(PACKAGE)) / 'launch' / INCLUDED
    return LaunchDescription([IncludeLaunchDescription(
        PythonLaunchDescriptionSource(str(path)), launch_arguments={'preset': PRESET}.items())])

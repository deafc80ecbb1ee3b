"""Launch the closed stiffness-control loop on the twin: ``sim_node`` -> ``estimator_node`` (12
load cells + IMU) -> ``stiffness_controller`` -> ``sim_node``:

    ros2 launch tensegrity_stiffness control.launch.py namespace:=/control \\
        params_file:=/path/to/config.yaml control_rate:=500.0 limits.tension_max:=3.0

The twin's load cells and IMU feed the estimator; the estimator's pose feeds the controller; the
controller's latched ``~/rest_lengths`` (motor commands) drive the twin and tell the estimator what
is commanded. All three read the same ``params_file`` (default: the installed
``config/default_joint.yaml``); any parameter of a node's table (docs/parameters.md) or
``use_sim_time`` given as ``name:=value`` is set on each of the three that has it, after the file,
typed by the table (:mod:`tensegrity_stiffness.ros.launch_parameters`). Targets go to
``stiffness_controller/target_pose`` and ``stiffness_controller/target_stiffness``
(docs/control.md). ``launch`` is not on PyPI: the test suite's launch checks compile files like
this one; ``test/ros/test_control_node.py`` starts the same three processes by hand.
"""

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.parameter_descriptions import ParameterValue

from tensegrity_stiffness.ros.launch_parameters import launch_node

PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'stiffness_controller'
SIM = 'sim_node'
ESTIMATOR = 'estimator_node'
CONFIG = 'default_joint.yaml'
#: Relative remappings: the three nodes share the namespace.
SIM_REMAPPINGS = [('~/rest_lengths', f'{EXECUTABLE}/rest_lengths')]
ESTIMATOR_REMAPPINGS = [('~/measured_tensions', f'{SIM}/measured_tensions'),
                        ('~/imu', f'{SIM}/imu'),
                        ('~/rest_lengths', f'{EXECUTABLE}/rest_lengths')]
CONTROLLER_REMAPPINGS = [('~/pose_estimate', f'{ESTIMATOR}/pose_estimate'),
                         ('~/wrench_estimate', f'{ESTIMATOR}/wrench_estimate')]


def generate_launch_description() -> LaunchDescription:
    default_params = str(Path(get_package_share_directory(PACKAGE)) / 'config' / CONFIG)
    namespace = LaunchConfiguration('namespace')
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='control',
                              description='namespace of the three nodes'),
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='ROS parameter file of the model (config/*.yaml); '
                              'single parameters: <name>:=<value>'),
        DeclareLaunchArgument('control_rate', default_value='500.0',
                              description='controller ticks per second, Hz'),
        launch_node(SIM, fixed=[{'sim.spine': False}], remappings=SIM_REMAPPINGS,
                    namespace=namespace),
        launch_node(ESTIMATOR, remappings=ESTIMATOR_REMAPPINGS, namespace=namespace),
        launch_node(EXECUTABLE, fixed=[{'control.rate': ParameterValue(
            LaunchConfiguration('control_rate'), value_type=float)}],
            remappings=CONTROLLER_REMAPPINGS, namespace=namespace),
    ])

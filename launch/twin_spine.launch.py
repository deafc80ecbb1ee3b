"""Launch the twin of the spine: ``sim_node`` (``sim.spine``) wired to ``spine_node``:

    ros2 launch tensegrity_stiffness twin_spine.launch.py namespace:=/twin \\
        params_file:=/path/to/config.yaml swing_amplitude:=0.01

The twin publishes the truth on ``sim_node/poses``, which is remapped onto the input
``~/poses`` of ``spine_node``; both read the same ``params_file`` (default: the installed
``config/default_spine.yaml``; single parameters as ``name:=value`` too). The description is
``twin.launch.py``'s, for the spine.
"""

import importlib.util
from pathlib import Path

from launch import LaunchDescription

KIND = 'spine'


def generate_launch_description() -> LaunchDescription:
    spec = importlib.util.spec_from_file_location(
        'twin_launch', Path(__file__).with_name('twin.launch.py'))
    twin = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(twin)
    return twin.twin_description(KIND)

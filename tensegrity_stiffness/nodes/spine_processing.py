"""The old home of ``spine_node``'s ROS-free behaviour, kept as a face that re-exports it
(public names and behaviour unchanged): :mod:`.spine_node` is its home.
"""

from tensegrity_stiffness.nodes.spine_node import (
    OUTPUT_NAMES,
    FloatArray,
    SpineOutputs,
    joint_health_in_chain,
    output_arrays,
    poses_input,
    require_finite,
    rest_lengths_input,
    screws_input,
    spine_outputs,
)

__all__ = [
    'OUTPUT_NAMES',
    'FloatArray',
    'SpineOutputs',
    'joint_health_in_chain',
    'output_arrays',
    'poses_input',
    'require_finite',
    'rest_lengths_input',
    'screws_input',
    'spine_outputs',
]

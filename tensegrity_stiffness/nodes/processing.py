"""The old home of ``stiffness_node``'s ROS-free behaviour, kept as a face that re-exports it
(public names and behaviour unchanged): :mod:`.stiffness_node` is its home.
"""

from tensegrity_stiffness.nodes.stiffness_node import (
    OUTPUT_NAMES,
    FloatArray,
    JointOutputs,
    finite_rows,
    frequency_report,
    joint_outputs,
    joint_outputs_batch,
    output_arrays,
    pose_input,
    require_finite,
    screw_input,
    screw_inputs,
    with_rest_lengths,
)

__all__ = [
    'OUTPUT_NAMES',
    'FloatArray',
    'JointOutputs',
    'finite_rows',
    'frequency_report',
    'joint_outputs',
    'joint_outputs_batch',
    'output_arrays',
    'pose_input',
    'require_finite',
    'screw_input',
    'screw_inputs',
    'with_rest_lengths',
]

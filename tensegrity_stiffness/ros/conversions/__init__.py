"""Pure conversions between numpy arrays and ROS 2 messages for tensegrity_stiffness.

No node and no ``rclpy.init()`` are needed: the functions only build and read message objects,
so they are tested by constructing messages directly. Every function validates its input at the
boundary and raises ``ValueError`` with a specific message (wrong shape / length, NaN or inf,
oversized arrays, non-unit quaternions, ...).

Modules
-------
arrays       numpy <-> ``std_msgs/Float64MultiArray`` with labelled row-major layouts.
geometry     ``geometry_msgs`` Wrench / Pose <-> numpy; rotation matrix <-> quaternion.
stamps       ``builtin_interfaces/Time`` <-> nanoseconds / seconds.
diagnostics  ``diagnostic_msgs/DiagnosticStatus`` and ``DiagnosticArray`` builders.
markers      ``visualization_msgs/MarkerArray`` of nodes and tension-coloured strings for RViz.
imu          ``sensor_msgs/Imu`` of the twin's IMU (angular velocity, specific force).
estimation   estimator_node's inputs and outputs (PoseWithCovarianceStamped, Imu gravity, measured
             arrays with NaN).
outputs      rclpy's message classes for :mod:`tensegrity_stiffness.nodes.messages`.
joint_outputs  the joint node's five per-input output messages and its markers.
spine_outputs  the spine node's seven per-input output messages and its markers.

The readers and the output messages themselves read and write by attribute and need no ROS
message package: they live in :mod:`tensegrity_stiffness.nodes.messages` (the bag command uses them
with rosbags' types) and are re-exported here for rclpy.

Orderings: wrench ``[fx fy fz mx my mz]``, screw ``[wx wy wz vx vy vz]``, quaternion
``[x y z w]``.
"""

from tensegrity_stiffness.ros.conversions.arrays import (
    CARTESIAN_TWIST_COL_LABEL,
    DEFAULT_MAX_LENGTH,
    SCREW_COL_LABEL,
    SCREW_LABEL,
    WRENCH_LABEL,
    WRENCH_ROW_LABEL,
    matrix_to_multiarray,
    multiarray_to_array,
    multiarray_to_matrix,
    set_multiarray_data,
    vector_to_multiarray,
)
from tensegrity_stiffness.ros.conversions.diagnostics import (
    diagnostic_array,
    diagnostic_status,
    format_value,
)
from tensegrity_stiffness.ros.conversions.geometry import (
    QUATERNION_UNIT_TOLERANCE,
    ROTATION_TOLERANCE,
    msg_to_wrench,
    pose_message_to_transform,
    quaternion_to_rotation,
    rotation_to_quaternion,
    set_wrench,
    transform_to_pose,
    wrench_to_msg,
)
from tensegrity_stiffness.ros.conversions.imu import imu_message, imu_to_arrays, write_imu
from tensegrity_stiffness.ros.conversions.joint_outputs import JointOutputMessages, joint_markers
from tensegrity_stiffness.ros.conversions.markers import marker_array, tension_color
from tensegrity_stiffness.ros.conversions.spine_outputs import SpineOutputMessages, spine_markers
from tensegrity_stiffness.ros.conversions.stamps import (
    stamp_from_nanoseconds,
    stamp_from_seconds,
    stamp_to_nanoseconds,
    stamp_to_seconds,
)

__all__ = [
    'CARTESIAN_TWIST_COL_LABEL',
    'DEFAULT_MAX_LENGTH',
    'QUATERNION_UNIT_TOLERANCE',
    'ROTATION_TOLERANCE',
    'SCREW_COL_LABEL',
    'SCREW_LABEL',
    'WRENCH_LABEL',
    'WRENCH_ROW_LABEL',
    'JointOutputMessages',
    'SpineOutputMessages',
    'diagnostic_array',
    'diagnostic_status',
    'format_value',
    'imu_message',
    'imu_to_arrays',
    'joint_markers',
    'marker_array',
    'matrix_to_multiarray',
    'msg_to_wrench',
    'multiarray_to_array',
    'multiarray_to_matrix',
    'pose_message_to_transform',
    'quaternion_to_rotation',
    'rotation_to_quaternion',
    'set_multiarray_data',
    'set_wrench',
    'spine_markers',
    'stamp_from_nanoseconds',
    'stamp_from_seconds',
    'stamp_to_nanoseconds',
    'stamp_to_seconds',
    'tension_color',
    'transform_to_pose',
    'vector_to_multiarray',
    'wrench_to_msg',
    'write_imu',
]

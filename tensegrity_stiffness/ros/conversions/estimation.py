"""Messages of ``estimator_node`` and ``spine_estimator_node``: their inputs decoded into
numbers (measured arrays with NaN for "not measured", ``PoseWithCovarianceStamped``, ``Imu``,
``WrenchStamped``) and their per-estimate outputs with rclpy's classes
(:class:`tensegrity_stiffness.nodes.messages.EstimatorOutputMessages` and
:class:`~tensegrity_stiffness.nodes.messages.SpineEstimatorOutputMessages`, preallocated and
refilled per estimate from the nodes' output tables in :mod:`tensegrity_stiffness.nodes.layouts`).

Pose covariance: ROS's ``PoseWithCovariance`` convention, the 6x6 row-major covariance of
``[dp; dtheta]`` with ``p -> p + dp``, ``R -> exp(hat(dtheta)) R``, both in the header's frame,
ordered ``[x y z rx ry rz]`` (:mod:`tensegrity_stiffness.estimation.sensor_models`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseWithCovariance, PoseWithCovarianceStamped, WrenchStamped
from numpy.typing import NDArray
from std_msgs.msg import Float64MultiArray

from tensegrity_stiffness.nodes import messages
from tensegrity_stiffness.nodes.messages import (
    multiarray_payload,
    write_pose_with_covariance_stamped,
)
from tensegrity_stiffness.ros.conversions.geometry import msg_to_wrench, pose_message_to_transform
from tensegrity_stiffness.ros.conversions.imu import imu_to_arrays
from tensegrity_stiffness.ros.conversions.outputs import RCLPY_TYPES

FloatArray = NDArray[np.float64]

__all__ = [
    'EstimatorOutputMessages',
    'SpineEstimatorOutputMessages',
    'imu_specific_force',
    'measured_values',
    'pose_with_covariance_to_arrays',
    'wrench_stamped_to_array',
    'write_pose_with_covariance',
]


def measured_values(msg: Float64MultiArray, max_length: int) -> FloatArray:
    """The payload of a measured-array message (``layout.data_offset`` honoured) as float64, NaN
    kept (not measured); ValueError when it has more than ``max_length`` elements (checked
    before any conversion) or a bad data offset. The caller checks the length and inf."""
    return multiarray_payload(msg, max_length)


def pose_with_covariance_to_arrays(msg: PoseWithCovariance
                                   ) -> tuple[FloatArray, FloatArray | None]:
    """((4, 4) transform, (6, 6) covariance) of a ``PoseWithCovariance``; the covariance is None
    when it is all zeros (not given). ValueError on a bad quaternion or a non-finite value; the
    estimator checks that a given covariance is symmetric positive definite."""
    T = pose_message_to_transform(msg.pose)
    cov = np.array(msg.covariance, dtype=np.float64).reshape(6, 6)
    if not np.all(np.isfinite(cov)):
        raise ValueError('pose covariance contains NaN or inf')
    return T, (None if not np.any(cov) else cov)


def write_pose_with_covariance(msg: PoseWithCovarianceStamped, transform: FloatArray,
                               covariance: FloatArray, stamp: Time, frame_id: str) -> None:
    """Header, pose of a (4, 4) transform and the (6, 6) covariance (row-major). The transform
    is an estimate's (a rotation by construction, checked finite): its rotation is not
    checked again."""
    write_pose_with_covariance_stamped(msg, (transform, covariance), stamp, frame_id)


def wrench_stamped_to_array(msg: WrenchStamped) -> FloatArray:
    """(6,) ``[fx fy fz mx my mz]`` of a ``WrenchStamped``; ValueError on NaN / inf."""
    return msg_to_wrench(msg.wrench)


def imu_specific_force(msg: Any) -> FloatArray:
    """(3,) specific force (m/s^2, the IMU's frame) of a ``sensor_msgs/Imu``; ValueError on
    NaN / inf."""
    return imu_to_arrays(msg)[1]


def imu_motion(msg: Any) -> tuple[FloatArray, FloatArray | None]:
    """(specific force (3,) m/s^2, angular velocity (3,) rad/s or None when the message says
    it has no gyro: ``angular_velocity_covariance[0] == -1``, the sensor_msgs convention) of a
    ``sensor_msgs/Imu``, in its frame; ValueError on NaN / inf."""
    angular_velocity, specific_force = imu_to_arrays(msg)
    has_gyro = msg.angular_velocity_covariance[0] != -1.0
    return specific_force, angular_velocity if has_gyro else None


class EstimatorOutputMessages(messages.EstimatorOutputMessages):
    """``estimator_node``'s per-estimate messages (rclpy), refilled by :meth:`fill`."""

    def __init__(self, string_names: tuple[str, ...]) -> None:
        super().__init__(tuple(string_names), RCLPY_TYPES)


class SpineEstimatorOutputMessages(messages.SpineEstimatorOutputMessages):
    """``spine_estimator_node``'s per-estimate messages (rclpy), refilled by :meth:`fill`."""

    def __init__(self, n_joints: int) -> None:
        super().__init__(n_joints, RCLPY_TYPES)

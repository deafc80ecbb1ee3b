"""Messages of ``estimator_node``: its inputs decoded into numbers (measured arrays with NaN
for "not measured", ``PoseWithCovarianceStamped``, ``Imu``, ``WrenchStamped``) and its seven
per-estimate outputs, preallocated and refilled per estimate.

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

from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion_unchecked
from tensegrity_stiffness.nodes.estimation_processing import (
    EstimatorOutputs,
    SpineEstimatorOutputs,
    output_arrays,
    spine_output_arrays,
)
from tensegrity_stiffness.nodes.layouts import (
    CARTESIAN_STIFFNESS_COL_LABEL,
    JOINTS_LABEL,
    SCREW_LABEL,
    STIFFNESS_COL_LABEL,
    STIFFNESS_ROW_LABEL,
    TIP_STIFFNESS_LABELS,
    tensions_label,
)
from tensegrity_stiffness.nodes.messages import multiarray_payload
from tensegrity_stiffness.ros.conversions.arrays import matrix_to_multiarray, vector_to_multiarray
from tensegrity_stiffness.ros.conversions.geometry import msg_to_wrench, pose_message_to_transform
from tensegrity_stiffness.ros.conversions.imu import imu_to_arrays
from tensegrity_stiffness.ros.conversions.outputs import (
    fill_outputs,
    write_payload,
    write_wrench_stamped,
)

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
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    pose = msg.pose.pose
    pose.position.x, pose.position.y, pose.position.z = transform[:3, 3].tolist()
    o = pose.orientation
    o.x, o.y, o.z, o.w = rotation_to_quaternion_unchecked(transform[:3, :3]).tolist()
    # A float64[36] field takes a numpy array of 36 as it is (any other sequence is checked
    # value by value): a copy, as the message keeps it.
    msg.pose.covariance = np.array(covariance, dtype=np.float64).reshape(36)


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


class EstimatorOutputMessages:
    """The seven per-estimate messages of ``estimator_node``, refilled by :meth:`fill`:
    ``~/pose_estimate``, ``~/wrench_estimate``, ``~/screw_estimate``, ``~/stiffness``,
    ``~/cartesian_stiffness``, ``~/string_tensions``, ``~/cartesian_stiffness_std`` (labelled
    as ``~/cartesian_stiffness``)."""

    def __init__(self, string_names: tuple[str, ...]) -> None:
        self.pose = PoseWithCovarianceStamped()
        self.wrench = WrenchStamped()
        self.screw = vector_to_multiarray(np.zeros(6), SCREW_LABEL)
        self.stiffness = matrix_to_multiarray(np.zeros((6, 6)), STIFFNESS_ROW_LABEL,
                                              STIFFNESS_COL_LABEL)
        self.cartesian_stiffness = matrix_to_multiarray(
            np.zeros((6, 6)), STIFFNESS_ROW_LABEL, CARTESIAN_STIFFNESS_COL_LABEL)
        self.tensions = vector_to_multiarray(np.zeros(len(string_names)),
                                             tensions_label(tuple(string_names)))
        self.cartesian_stiffness_std = matrix_to_multiarray(
            np.zeros((6, 6)), STIFFNESS_ROW_LABEL, CARTESIAN_STIFFNESS_COL_LABEL)

    def messages(self) -> tuple[Any, ...]:
        """The messages in topic order (see the class docstring)."""
        return (self.pose, self.wrench, self.screw, self.stiffness, self.cartesian_stiffness,
                self.tensions, self.cartesian_stiffness_std)

    def fill(self, outputs: EstimatorOutputs, stamp: Time, frame_id: str,
             wanted: tuple[bool, ...] | None = None) -> None:
        """Set the messages (those flagged in ``wanted``, :meth:`messages` order) from one
        estimate whose arrays :func:`~tensegrity_stiffness.nodes.estimation_processing.
        estimator_outputs` checked finite."""
        transform, covariance, *rest = output_arrays(outputs)
        if wanted is None or wanted[0]:
            write_pose_with_covariance(self.pose, transform, covariance, stamp, frame_id)
        fill_outputs(self.messages()[1:], rest, (write_wrench_stamped,) + (write_payload,) * 5,
                     stamp, frame_id, None if wanted is None else wanted[1:])



class SpineEstimatorOutputMessages:
    """The five per-estimate messages of ``spine_estimator_node``: ``~/screws_estimate`` (N x 6,
    joint-major), ``~/tip_pose_estimate`` (tool frame in the base, with covariance),
    ``~/tip_wrench_estimate`` (base, about its origin), ``~/tip_stiffness_base`` and
    ``~/tip_stiffness_base_std`` (labelled as ``spine_node``'s ``~/tip_stiffness_base``)."""

    def __init__(self, n_joints: int) -> None:
        self.screws = matrix_to_multiarray(np.zeros((n_joints, 6)), JOINTS_LABEL, SCREW_LABEL)
        self.pose = PoseWithCovarianceStamped()
        self.wrench = WrenchStamped()
        rows, cols = TIP_STIFFNESS_LABELS['base']
        self.stiffness = matrix_to_multiarray(np.zeros((6, 6)), rows, cols)
        self.stiffness_std = matrix_to_multiarray(np.zeros((6, 6)), rows, cols)

    def messages(self) -> tuple[Any, ...]:
        """The messages in topic order (see the class docstring)."""
        return (self.screws, self.pose, self.wrench, self.stiffness, self.stiffness_std)

    def fill(self, outputs: SpineEstimatorOutputs, stamp: Time, frame_id: str,
             wanted: tuple[bool, ...] | None = None) -> None:
        """Set the messages (those flagged in ``wanted``) from one estimate whose arrays
        :func:`~tensegrity_stiffness.nodes.estimation_processing.spine_estimator_outputs` checked
        finite."""
        screws, transform, covariance, wrench, stiffness, std = spine_output_arrays(outputs)
        if wanted is None or wanted[1]:
            write_pose_with_covariance(self.pose, transform, covariance, stamp, frame_id)
        messages = self.messages()
        fill_outputs((messages[0], *messages[2:]), (screws, wrench, stiffness, std),
                     (write_payload, write_wrench_stamped, write_payload, write_payload),
                     stamp, frame_id,
                     None if wanted is None else (wanted[0], *wanted[2:]))

"""Messages of ``estimator_node`` and ``spine_estimator_node``: their inputs decoded into
numbers (measured arrays with NaN for "not measured", ``PoseWithCovarianceStamped``, ``Imu``,
``WrenchStamped``) and their per-estimate outputs, preallocated and refilled per estimate from
one output table per node (:func:`estimator_output_table`, :func:`spine_estimator_output_table`:
name, message type, writer, value).

Pose covariance: ROS's ``PoseWithCovariance`` convention, the 6x6 row-major covariance of
``[dp; dtheta]`` with ``p -> p + dp``, ``R -> exp(hat(dtheta)) R``, both in the header's frame,
ordered ``[x y z rx ry rz]`` (:mod:`tensegrity_stiffness.estimation.sensor_models`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseWithCovariance, PoseWithCovarianceStamped, WrenchStamped
from numpy.typing import NDArray
from std_msgs.msg import Float64MultiArray

from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion_unchecked
from tensegrity_stiffness.msg import StampedMatrix
from tensegrity_stiffness.nodes.layouts import (
    CARTESIAN_STIFFNESS_COL_LABEL,
    ESTIMATOR_OUTPUTS,
    JOINT_STAMPED_OUTPUTS,
    JOINTS_LABEL,
    SCREW_LABEL,
    SPINE_ESTIMATOR_OUTPUTS,
    SPINE_STAMPED_OUTPUTS,
    STAMPED_MATRIX,
    STIFFNESS_COL_LABEL,
    STIFFNESS_ROW_LABEL,
    TIP_STIFFNESS_LABELS,
    OutputLayout,
    matrix_dims,
    tensions_label,
)
from tensegrity_stiffness.nodes.messages import (
    multiarray_payload,
    new_message,
    stamped_matrix_writer,
)
from tensegrity_stiffness.ros.conversions.arrays import matrix_to_multiarray, vector_to_multiarray
from tensegrity_stiffness.ros.conversions.geometry import msg_to_wrench, pose_message_to_transform
from tensegrity_stiffness.ros.conversions.imu import imu_to_arrays
from tensegrity_stiffness.ros.conversions.outputs import (
    RCLPY_TYPES,
    write_payload,
    write_wrench_stamped,
)

FloatArray = NDArray[np.float64]

__all__ = [
    'EstimatorOutputMessages',
    'OutputRow',
    'SpineEstimatorOutputMessages',
    'TableOutputMessages',
    'estimator_output_table',
    'imu_specific_force',
    'measured_values',
    'pose_with_covariance_to_arrays',
    'spine_estimator_output_table',
    'table_topics',
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


@dataclass(frozen=True)
class OutputRow:
    """One output of an estimator node (a row of its output table): the topic relative to
    the node, the message type, a new preallocated message of it, the writer that refills it
    per estimate (``write(msg, value, stamp, frame_id)``) and the value of an estimate it
    carries (``value(outputs)``)."""

    name: str
    msg_type: type
    new: Callable[[], Any]
    write: Callable[[Any, Any, Time, str], None]
    value: Callable[[Any], Any]


def _write_pose_row(msg: PoseWithCovarianceStamped, value: tuple[FloatArray, FloatArray],
                    stamp: Time, frame_id: str) -> None:
    write_pose_with_covariance(msg, *value, stamp, frame_id)


def _matrix(rows: int, cols: int, row_label: str, col_label: str) -> Callable[[], Any]:
    return lambda: matrix_to_multiarray(np.zeros((rows, cols)), row_label, col_label)


def _stamped_matrix(row_label: str, col_label: str) -> Callable[[], Any]:
    layout = OutputLayout(STAMPED_MATRIX, tuple(matrix_dims(6, 6, row_label, col_label)))
    return lambda: new_message(layout, RCLPY_TYPES)


#: Writes a ``StampedMatrix``: its header and data (labels and counts set once).
write_stamped_matrix = stamped_matrix_writer(RCLPY_TYPES)

#: The estimators' output names (their one home: ``nodes/layouts.py``), one per table row.
POSE, WRENCH, SCREW, STIFFNESS, CARTESIAN_STIFFNESS, TENSIONS, CARTESIAN_STIFFNESS_STD = \
    ESTIMATOR_OUTPUTS
STIFFNESS_STAMPED, CARTESIAN_STIFFNESS_STAMPED = JOINT_STAMPED_OUTPUTS


def estimator_output_table(string_names: tuple[str, ...]) -> tuple[OutputRow, ...]:
    """``estimator_node``'s outputs in publishing order: the pose (with covariance), the load,
    the screw, K, K_c, the tensions, the std of K_c (labelled as K_c), then K and K_c stamped
    with the estimate's stamp and frame (``msg/StampedMatrix``, ``stiffness_node``'s names).
    Adding or reordering an output is one row."""
    rows, kcols = STIFFNESS_ROW_LABEL, CARTESIAN_STIFFNESS_COL_LABEL
    return (
        OutputRow(POSE, PoseWithCovarianceStamped, PoseWithCovarianceStamped, _write_pose_row,
                  lambda o: (o.estimate.transform, o.estimate.covariance)),
        OutputRow(WRENCH, WrenchStamped, WrenchStamped, write_wrench_stamped,
                  lambda o: o.estimate.external_wrench),
        OutputRow(SCREW, Float64MultiArray,
                  lambda: vector_to_multiarray(np.zeros(6), SCREW_LABEL), write_payload,
                  lambda o: o.estimate.screw),
        OutputRow(STIFFNESS, Float64MultiArray, _matrix(6, 6, rows, STIFFNESS_COL_LABEL),
                  write_payload, lambda o: o.state.stiffness),
        OutputRow(CARTESIAN_STIFFNESS, Float64MultiArray, _matrix(6, 6, rows, kcols),
                  write_payload, lambda o: o.state.cartesian_stiffness),
        OutputRow(TENSIONS, Float64MultiArray,
                  lambda: vector_to_multiarray(np.zeros(len(string_names)),
                                               tensions_label(string_names)),
                  write_payload, lambda o: o.state.tensions),
        OutputRow(CARTESIAN_STIFFNESS_STD, Float64MultiArray, _matrix(6, 6, rows, kcols),
                  write_payload, lambda o: o.estimate.cartesian_stiffness_std),
        OutputRow(STIFFNESS_STAMPED, StampedMatrix, _stamped_matrix(rows, STIFFNESS_COL_LABEL),
                  write_stamped_matrix, lambda o: o.state.stiffness),
        OutputRow(CARTESIAN_STIFFNESS_STAMPED, StampedMatrix, _stamped_matrix(rows, kcols),
                  write_stamped_matrix, lambda o: o.state.cartesian_stiffness),
    )


(SCREWS, TIP_POSE, TIP_WRENCH, TIP_STIFFNESS_BASE, TIP_STIFFNESS_BASE_STD) = \
    SPINE_ESTIMATOR_OUTPUTS
TIP_STIFFNESS_BASE_STAMPED = next(name for name, of in SPINE_STAMPED_OUTPUTS.items()
                                  if of == TIP_STIFFNESS_BASE)


def spine_estimator_output_table(n_joints: int) -> tuple[OutputRow, ...]:
    """``spine_estimator_node``'s outputs in publishing order: the screws (N x 6,
    joint-major), the tip pose (tool frame in the base, with covariance), the tip load (base,
    about its origin), the tip stiffness in the base and its std (labelled as ``spine_node``'s
    ``~/tip_stiffness_base``), then the tip stiffness stamped with the estimate's stamp and
    frame (``spine_node``'s name)."""
    rows, cols = TIP_STIFFNESS_LABELS['base']
    return (
        OutputRow(SCREWS, Float64MultiArray, _matrix(n_joints, 6, JOINTS_LABEL, SCREW_LABEL),
                  write_payload, lambda o: o.estimate.screws),
        OutputRow(TIP_POSE, PoseWithCovarianceStamped, PoseWithCovarianceStamped,
                  _write_pose_row,
                  lambda o: (o.estimate.tip_transform, o.estimate.tip_pose_covariance)),
        OutputRow(TIP_WRENCH, WrenchStamped, WrenchStamped, write_wrench_stamped,
                  lambda o: o.estimate.tip_wrench),
        OutputRow(TIP_STIFFNESS_BASE, Float64MultiArray, _matrix(6, 6, rows, cols),
                  write_payload, lambda o: o.estimate.tip_stiffness),
        OutputRow(TIP_STIFFNESS_BASE_STD, Float64MultiArray, _matrix(6, 6, rows, cols),
                  write_payload, lambda o: o.estimate.tip_stiffness_std),
        OutputRow(TIP_STIFFNESS_BASE_STAMPED, StampedMatrix, _stamped_matrix(rows, cols),
                  write_stamped_matrix, lambda o: o.estimate.tip_stiffness),
    )


def table_topics(table: tuple[OutputRow, ...]) -> tuple[tuple[type, str], ...]:
    """``(message type, '~/<name>')`` of an output table: a node's ``OUTPUT_TOPICS``."""
    return tuple((row.msg_type, f'~/{row.name}') for row in table)


class TableOutputMessages:
    """One preallocated message per row of an output table, refilled by :meth:`fill` from an
    estimate whose arrays the processing checked finite."""

    def __init__(self, table: tuple[OutputRow, ...]) -> None:
        self.table = table
        self._messages = tuple(row.new() for row in table)

    def messages(self) -> tuple[Any, ...]:
        """The messages in the table's order."""
        return self._messages

    def fill(self, outputs: Any, stamp: Time, frame_id: str,
             wanted: tuple[bool, ...] | None = None) -> None:
        """Set the messages flagged in ``wanted`` (default all, :meth:`messages` order)."""
        for k, (row, msg) in enumerate(zip(self.table, self._messages, strict=True)):
            if wanted is None or wanted[k]:
                row.write(msg, row.value(outputs), stamp, frame_id)


class EstimatorOutputMessages(TableOutputMessages):
    """``estimator_node``'s per-estimate messages (:func:`estimator_output_table`)."""

    def __init__(self, string_names: tuple[str, ...]) -> None:
        super().__init__(estimator_output_table(tuple(string_names)))


class SpineEstimatorOutputMessages(TableOutputMessages):
    """``spine_estimator_node``'s per-estimate messages (:func:`spine_estimator_output_table`)."""

    def __init__(self, n_joints: int) -> None:
        super().__init__(spine_estimator_output_table(n_joints))

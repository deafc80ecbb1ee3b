"""``sensor_msgs/Imu`` <-> numpy: angular velocity and specific force of a link (no orientation).

The twin's IMU (:class:`tensegrity_stiffness.simulation.twin_sensors.ImuReading`) measures in
the link's own frame: ``angular_velocity`` (rad/s) and ``linear_acceleration`` = the specific
force (m/s^2, acceleration minus gravity, as a real accelerometer). It gives no orientation
estimate, so ``orientation_covariance[0] = -1`` (the message's convention for "no
orientation"); the other two covariances are diagonal with the noise variances (0: not known to
be noisy).
"""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from numpy.typing import ArrayLike, NDArray
from sensor_msgs.msg import Imu

from tensegrity_stiffness.geometry.validation import finite_array_of_shape

FloatArray = NDArray[np.float64]

__all__ = ['imu_message', 'imu_to_arrays', 'write_imu']


def _diagonal(variance: float) -> list[float]:
    return [variance, 0.0, 0.0, 0.0, variance, 0.0, 0.0, 0.0, variance]


def imu_message(frame_id: str, gyro_std: float = 0.0, accelerometer_std: float = 0.0) -> Imu:
    """A preallocated Imu message: frame, no orientation, covariances of the noise (the
    readings are written per sample with :func:`write_imu`)."""
    msg = Imu()
    msg.header.frame_id = frame_id
    msg.orientation.w = 1.0
    msg.orientation_covariance = [-1.0] + [0.0] * 8
    msg.angular_velocity_covariance = _diagonal(float(gyro_std) ** 2)
    msg.linear_acceleration_covariance = _diagonal(float(accelerometer_std) ** 2)
    return msg


def write_imu(msg: Imu, angular_velocity: ArrayLike, specific_force: ArrayLike,
              stamp: Time) -> Imu:
    """Write one reading (rad/s, m/s^2, in the link's frame) and its stamp; ValueError when a
    value is not finite or not 3 long."""
    w = finite_array_of_shape('angular_velocity', angular_velocity, (3,))
    a = finite_array_of_shape('specific_force', specific_force, (3,))
    msg.header.stamp = stamp
    msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = w.tolist()
    msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = a.tolist()
    return msg


def imu_to_arrays(msg: Imu) -> tuple[FloatArray, FloatArray]:
    """(angular velocity (3,), specific force (3,)) of an Imu message; ValueError on NaN/inf."""
    w = msg.angular_velocity
    a = msg.linear_acceleration
    return (finite_array_of_shape('angular_velocity', [w.x, w.y, w.z], (3,)),
            finite_array_of_shape('linear_acceleration', [a.x, a.y, a.z], (3,)))

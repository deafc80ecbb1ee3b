"""numpy <-> ``geometry_msgs`` (Wrench, Pose); rotation matrix <-> unit quaternion re-exported
from :mod:`tensegrity_stiffness.geometry.quaternion`.

Conventions: quaternions are ROS-ordered ``[x, y, z, w]`` (scalar last) and returned with
``w >= 0``; wrenches are ``[fx fy fz mx my mz]`` (force first, N and N*m); homogeneous transforms
are (4, 4) with rotation ``T[:3, :3]`` and translation ``T[:3, 3]`` (m), mapping coordinates in
the child frame to the parent frame (a ``Pose`` of frame {2} in {1} is the transform 1_T_2).
:func:`pose_message_to_transform` (and the field writers) read any message implementation and live
in
:mod:`tensegrity_stiffness.nodes.messages`; re-exported here.
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Point, Pose, Quaternion, Vector3, Wrench
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.quaternion import (
    QUATERNION_UNIT_TOLERANCE,
    QUATERNION_ZERO_NORM,
    ROTATION_TOLERANCE,
    quaternion_to_rotation,
    rotation_to_quaternion,
)
from tensegrity_stiffness.geometry.validation import finite_array_of_shape
from tensegrity_stiffness.nodes.messages import (
    pose_message_to_transform,
    pose_values,
    write_wrench,
)

__all__ = [
    'QUATERNION_UNIT_TOLERANCE',
    'QUATERNION_ZERO_NORM',
    'ROTATION_TOLERANCE',
    'msg_to_wrench',
    'pose_message_to_transform',
    'quaternion_to_rotation',
    'rotation_to_quaternion',
    'transform_to_pose',
    'wrench_to_msg',
]

FloatArray = NDArray[np.float64]


def wrench_to_msg(wrench: ArrayLike) -> Wrench:
    """``geometry_msgs/Wrench`` from a (6,) array ``[fx fy fz mx my mz]`` (N, N*m)."""
    w = finite_array_of_shape('wrench', wrench, (6,))
    return Wrench(force=Vector3(x=float(w[0]), y=float(w[1]), z=float(w[2])),
                  torque=Vector3(x=float(w[3]), y=float(w[4]), z=float(w[5])))


def set_wrench(msg: Wrench, wrench: ArrayLike) -> Wrench:
    """Write a (6,) array ``[fx fy fz mx my mz]`` into an existing ``Wrench`` (reused messages)."""
    return write_wrench(msg, finite_array_of_shape('wrench', wrench, (6,)))


def msg_to_wrench(msg: Wrench) -> FloatArray:
    """(6,) array ``[fx fy fz mx my mz]`` of a ``geometry_msgs/Wrench``; ValueError on NaN/inf."""
    return finite_array_of_shape('wrench', [msg.force.x, msg.force.y, msg.force.z,
                                            msg.torque.x, msg.torque.y, msg.torque.z], None)


def transform_to_pose(transform: ArrayLike, tolerance: float = ROTATION_TOLERANCE) -> Pose:
    """``geometry_msgs/Pose`` of a (4, 4) homogeneous transform.

    Raises
    ------
    ValueError
        If T is not finite (4, 4), its last row is not [0 0 0 1] within ``tolerance``, or its
        rotation block is not a rotation (see :func:`rotation_to_quaternion`).
    """
    (px, py, pz), (x, y, z, w) = pose_values(transform, tolerance)
    return Pose(position=Point(x=px, y=py, z=pz), orientation=Quaternion(x=x, y=y, z=z, w=w))

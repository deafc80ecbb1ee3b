"""numpy <-> ``geometry_msgs`` (Wrench, Pose); rotation matrix <-> unit quaternion re-exported
from :mod:`tensegrity_stiffness.quaternion`.

Conventions: quaternions are ROS-ordered ``[x, y, z, w]`` (scalar last) and returned with
``w >= 0``; wrenches are ``[fx fy fz mx my mz]`` (force first, N and N*m); homogeneous transforms
are (4, 4) with rotation ``T[:3, :3]`` and translation ``T[:3, 3]`` (m), mapping coordinates in
the child frame to the parent frame (a ``Pose`` of frame {2} in {1} is the transform 1_T_2).
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Point, Pose, Quaternion, Vector3, Wrench
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.quaternion import (
    QUATERNION_UNIT_TOLERANCE,
    QUATERNION_ZERO_NORM,
    ROTATION_TOLERANCE,
    quaternion_to_rotation,
    rotation_to_quaternion,
)
from tensegrity_stiffness.validation import finite_array_of_shape

__all__ = [
    'QUATERNION_UNIT_TOLERANCE',
    'QUATERNION_ZERO_NORM',
    'ROTATION_TOLERANCE',
    'msg_to_wrench',
    'pose_to_transform',
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


def write_wrench(msg: Wrench, wrench: NDArray[np.float64]) -> Wrench:
    """:func:`set_wrench` without its checks, for a (6,) array already checked finite."""
    f, t = msg.force, msg.torque
    f.x, f.y, f.z, t.x, t.y, t.z = wrench.tolist()
    return msg


def msg_to_wrench(msg: Wrench) -> FloatArray:
    """(6,) array ``[fx fy fz mx my mz]`` of a ``geometry_msgs/Wrench``; ValueError on NaN/inf."""
    return finite_array_of_shape('wrench', [msg.force.x, msg.force.y, msg.force.z,
                                            msg.torque.x, msg.torque.y, msg.torque.z], None)


def pose_to_transform(pose: Pose,
                      unit_tolerance: float = QUATERNION_UNIT_TOLERANCE) -> FloatArray:
    """(4, 4) homogeneous transform of a ``geometry_msgs/Pose`` (position in m).

    The orientation is validated as in :func:`quaternion_to_rotation` (finite, non-zero, unit
    norm within ``unit_tolerance``; renormalised within it).

    Raises
    ------
    ValueError
        Non-finite position, or an invalid orientation quaternion.
    """
    p = finite_array_of_shape('pose position',
                              [pose.position.x, pose.position.y, pose.position.z], None)
    o = pose.orientation
    T = np.eye(4)
    T[:3, :3] = quaternion_to_rotation([o.x, o.y, o.z, o.w], unit_tolerance=unit_tolerance)
    T[:3, 3] = p
    return T


def transform_to_pose(transform: ArrayLike, tolerance: float = ROTATION_TOLERANCE) -> Pose:
    """``geometry_msgs/Pose`` of a (4, 4) homogeneous transform.

    Raises
    ------
    ValueError
        If T is not finite (4, 4), its last row is not [0 0 0 1] within ``tolerance``, or its
        rotation block is not a rotation (see :func:`rotation_to_quaternion`).
    """
    T = finite_array_of_shape('transform', transform, (4, 4))
    if float(np.max(np.abs(T[3] - np.array([0.0, 0.0, 0.0, 1.0])))) > tolerance:
        raise ValueError(f'transform last row must be [0 0 0 1], got {T[3].tolist()}')
    x, y, z, w = rotation_to_quaternion(T[:3, :3], tolerance=tolerance)
    return Pose(position=Point(x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
                orientation=Quaternion(x=float(x), y=float(y), z=float(z), w=float(w)))

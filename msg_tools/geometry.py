"""numpy <-> ``geometry_msgs`` (Wrench, Pose) and rotation matrix <-> unit quaternion.

Conventions: quaternions are ROS-ordered ``[x, y, z, w]`` (scalar last) and returned with
``w >= 0``; wrenches are ``[fx fy fz mx my mz]`` (force first, N and N*m); homogeneous transforms
are (4, 4) with rotation ``T[:3, :3]`` and translation ``T[:3, 3]`` (m), mapping coordinates in
the child frame to the parent frame (a ``Pose`` of frame {2} in {1} is the transform 1_T_2).
"""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Point, Pose, Quaternion, Vector3, Wrench
from numpy.typing import ArrayLike, NDArray

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

#: Largest accepted deviation of a quaternion norm from 1; within it the quaternion is
#: renormalised silently (float32 sources, rounded hand-typed values), beyond it rejected.
#: Same order as RViz's quaternion validation.
QUATERNION_UNIT_TOLERANCE = 1e-3
#: Quaternion norms below this are treated as zero (no rotation can be recovered).
QUATERNION_ZERO_NORM = 1e-12
#: Largest accepted max-abs deviation of R^T R from I (and of the last row of T from [0 0 0 1]).
ROTATION_TOLERANCE = 1e-6


def _finite(value: ArrayLike, shape: tuple[int, ...], name: str) -> FloatArray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{name} must be numeric: {exc}') from exc
    if arr.shape != shape:
        raise ValueError(f'{name} must have shape {shape}, got {arr.shape}')
    if not np.all(np.isfinite(arr)):
        raise ValueError(f'{name} contains NaN or inf')
    return arr


def wrench_to_msg(wrench: ArrayLike) -> Wrench:
    """``geometry_msgs/Wrench`` from a (6,) array ``[fx fy fz mx my mz]`` (N, N*m)."""
    w = _finite(wrench, (6,), 'wrench')
    return Wrench(force=Vector3(x=float(w[0]), y=float(w[1]), z=float(w[2])),
                  torque=Vector3(x=float(w[3]), y=float(w[4]), z=float(w[5])))


def set_wrench(msg: Wrench, wrench: ArrayLike) -> Wrench:
    """Write a (6,) array ``[fx fy fz mx my mz]`` into an existing ``Wrench`` (reused messages)."""
    w = _finite(wrench, (6,), 'wrench').tolist()
    f, t = msg.force, msg.torque
    f.x, f.y, f.z, t.x, t.y, t.z = w
    return msg


def msg_to_wrench(msg: Wrench) -> FloatArray:
    """(6,) array ``[fx fy fz mx my mz]`` of a ``geometry_msgs/Wrench``; ValueError on NaN/inf."""
    w = np.array([msg.force.x, msg.force.y, msg.force.z,
                  msg.torque.x, msg.torque.y, msg.torque.z], dtype=np.float64)
    if not np.all(np.isfinite(w)):
        raise ValueError('wrench contains NaN or inf')
    return w


def quaternion_to_rotation(quaternion: ArrayLike,
                           unit_tolerance: float = QUATERNION_UNIT_TOLERANCE) -> FloatArray:
    """(3, 3) rotation matrix of a quaternion ``[x, y, z, w]``.

    The quaternion must be finite and of unit norm within ``unit_tolerance`` (absolute deviation
    of the norm from 1); it is renormalised before use.

    Raises
    ------
    ValueError
        ``'NaN or inf'``, ``'zero norm'`` or ``'not a unit quaternion'``.
    """
    q = _finite(quaternion, (4,), 'quaternion')
    norm = float(np.linalg.norm(q))
    if norm < QUATERNION_ZERO_NORM:
        raise ValueError('quaternion has zero norm')
    if abs(norm - 1.0) > unit_tolerance:
        raise ValueError(
            f'not a unit quaternion: norm {norm:.9g} deviates from 1 by more than '
            f'unit_tolerance={unit_tolerance:g}')
    x, y, z, w = q / norm
    return np.array([
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
        [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
        [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
    ])


def rotation_to_quaternion(rotation: ArrayLike,
                           tolerance: float = ROTATION_TOLERANCE) -> FloatArray:
    """Unit quaternion ``[x, y, z, w]`` (``w >= 0``) of a (3, 3) rotation matrix.

    Shepperd's method (J. Guidance and Control 1(3), 1978): of the four candidates
    ``4w^2 = 1 + tr R`` and ``4x^2 = 1 + 2 R00 - tr R`` (and y, z alike) the largest is taken
    as the pivot, so the square root and the division never act on a small number; accurate to
    machine precision over all of SO(3), including rotations by pi.

    Raises
    ------
    ValueError
        If R is not finite, not (3, 3), not orthonormal within ``tolerance`` (max-abs entry of
        R^T R - I) or has det R < 0.
    """
    R = _finite(rotation, (3, 3), 'rotation')
    deviation = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if deviation > tolerance:
        raise ValueError(
            f'rotation is not orthonormal: max |R^T R - I| = {deviation:.3g} > '
            f'tolerance={tolerance:g}')
    if np.linalg.det(R) < 0.0:
        raise ValueError('rotation has det < 0 (a reflection, not a rotation)')
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    pivots = (trace, R[0, 0], R[1, 1], R[2, 2])
    k = int(np.argmax(pivots))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + trace)  # s = 4w
        q = np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s,
                      (R[1, 0] - R[0, 1]) / s, 0.25 * s])
    elif k == 1:
        s = 2.0 * np.sqrt(1.0 + 2.0 * R[0, 0] - trace)  # s = 4x
        q = np.array([0.25 * s, (R[0, 1] + R[1, 0]) / s,
                      (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s])
    elif k == 2:
        s = 2.0 * np.sqrt(1.0 + 2.0 * R[1, 1] - trace)  # s = 4y
        q = np.array([(R[0, 1] + R[1, 0]) / s, 0.25 * s,
                      (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s])
    else:
        s = 2.0 * np.sqrt(1.0 + 2.0 * R[2, 2] - trace)  # s = 4z
        q = np.array([(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s,
                      0.25 * s, (R[1, 0] - R[0, 1]) / s])
    q /= np.linalg.norm(q)
    if q[3] < 0.0:
        q = -q
    return q


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
    p = np.array([pose.position.x, pose.position.y, pose.position.z], dtype=np.float64)
    if not np.all(np.isfinite(p)):
        raise ValueError('pose position contains NaN or inf')
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
    T = _finite(transform, (4, 4), 'transform')
    if float(np.max(np.abs(T[3] - np.array([0.0, 0.0, 0.0, 1.0])))) > tolerance:
        raise ValueError(f'transform last row must be [0 0 0 1], got {T[3].tolist()}')
    x, y, z, w = rotation_to_quaternion(T[:3, :3], tolerance=tolerance)
    return Pose(position=Point(x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
                orientation=Quaternion(x=float(x), y=float(y), z=float(z), w=float(w)))

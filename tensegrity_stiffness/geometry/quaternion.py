"""Unit quaternions (ROS order ``[x, y, z, w]``, scalar last) <-> rotation matrices.

Pure numpy, shared by the node's message conversions
(``tensegrity_stiffness.ros.conversions.geometry``) and the command
line, so that a pose means the same everywhere: a quaternion is accepted when finite, non-zero
and of unit norm within :data:`QUATERNION_UNIT_TOLERANCE` (then renormalised); a rotation matrix
when orthonormal within :data:`ROTATION_TOLERANCE` with det > 0. Quaternions are returned with
``w >= 0``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.errors import BadQuaternionError
from tensegrity_stiffness.geometry.validation import finite_array_of_shape

__all__ = [
    'QUATERNION_UNIT_TOLERANCE',
    'QUATERNION_ZERO_NORM',
    'ROTATION_TOLERANCE',
    'quaternion_to_rotation',
    'rotation_to_quaternion',
    'unit_quaternions_to_rotations',
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



def quaternion_to_rotation(quaternion: ArrayLike,
                           unit_tolerance: float = QUATERNION_UNIT_TOLERANCE) -> FloatArray:
    """(3, 3) rotation matrix of a quaternion ``[x, y, z, w]``.

    The quaternion must be finite and of unit norm within ``unit_tolerance`` (absolute deviation
    of the norm from 1); it is renormalised before use.

    Raises
    ------
    BadQuaternionError
        (a ValueError) ``'NaN or inf'``, ``'zero norm'`` or ``'not a unit quaternion'``.
    """
    try:
        q = finite_array_of_shape('quaternion', quaternion, (4,))
    except ValueError as exc:
        raise BadQuaternionError(str(exc)) from None
    norm = float(np.linalg.norm(q))
    if norm < QUATERNION_ZERO_NORM:
        raise BadQuaternionError('quaternion has zero norm')
    if abs(norm - 1.0) > unit_tolerance:
        raise BadQuaternionError(
            f'not a unit quaternion: norm {norm:.9g} deviates from 1 by more than '
            f'unit_tolerance={unit_tolerance:g}')
    return unit_quaternions_to_rotations(q / norm)


def unit_quaternions_to_rotations(q: FloatArray) -> FloatArray:
    """(..., 3, 3) rotation matrices of unit quaternions ``[x, y, z, w]`` (..., 4), unchecked
    (the callers check and normalise: :func:`quaternion_to_rotation`, and the batched pose
    readers)."""
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[..., 0, 1] = 2.0 * (x * y - z * w)
    R[..., 0, 2] = 2.0 * (x * z + y * w)
    R[..., 1, 0] = 2.0 * (x * y + z * w)
    R[..., 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[..., 1, 2] = 2.0 * (y * z - x * w)
    R[..., 2, 0] = 2.0 * (x * z - y * w)
    R[..., 2, 1] = 2.0 * (y * z + x * w)
    R[..., 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return R


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
    R = finite_array_of_shape('rotation', rotation, (3, 3))
    deviation = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if deviation > tolerance:
        raise ValueError(
            f'rotation is not orthonormal: max |R^T R - I| = {deviation:.3g} > '
            f'tolerance={tolerance:g}')
    if np.linalg.det(R) < 0.0:
        raise ValueError('rotation has det < 0 (a reflection, not a rotation)')
    return rotation_to_quaternion_unchecked(R)


def rotation_to_quaternion_unchecked(rotation: FloatArray) -> FloatArray:
    """:func:`rotation_to_quaternion` (Shepperd's method, ``w >= 0``) of a finite (3, 3)
    rotation known to be one (e.g. ``exp`` of a screw, an estimate's pose): no checks, in
    floats (a publisher's per-message path)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rotation.tolist()
    trace = r00 + r11 + r22
    pivots = (trace, r00, r11, r22)
    k = max(range(4), key=pivots.__getitem__)  # the first largest, as np.argmax
    if k == 0:
        s = 2.0 * math.sqrt(1.0 + trace)  # s = 4w
        q = ((r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s, 0.25 * s)
    elif k == 1:
        s = 2.0 * math.sqrt(1.0 + 2.0 * r00 - trace)  # s = 4x
        q = (0.25 * s, (r01 + r10) / s, (r02 + r20) / s, (r21 - r12) / s)
    elif k == 2:
        s = 2.0 * math.sqrt(1.0 + 2.0 * r11 - trace)  # s = 4y
        q = ((r01 + r10) / s, 0.25 * s, (r12 + r21) / s, (r02 - r20) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + 2.0 * r22 - trace)  # s = 4z
        q = ((r02 + r20) / s, (r12 + r21) / s, 0.25 * s, (r10 - r01) / s)
    x, y, z, w = q
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if w < 0.0:
        norm = -norm
    return np.array([x / norm, y / norm, z / norm, w / norm])

"""Rigid transforms: the one parser of a pose given as a (4, 4) matrix or ``[x y z qx qy qz qw]``
(metres, unit quaternion in ROS order), the inverse of a rigid transform and the adjoint of a
pose in both twist orders.

Every pose the library takes (link offsets, tool frames, measured poses, recorded poses, the
controllers' frames) goes through :func:`rigid_transform`, so it is checked the same way.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.quaternion import quaternion_to_rotation
from tensegrity_stiffness.geometry.screw import hat3
from tensegrity_stiffness.geometry.validation import finite_array

FloatArray = NDArray[np.float64]

#: Largest accepted max-abs deviation of R^T R from I in a (4, 4) pose.
RIGID_TOLERANCE = 1e-9


def pose_vector_to_transform(pose: ArrayLike, name: str = 'pose') -> FloatArray:
    """(4, 4) transform of ``[x y z qx qy qz qw]`` (metres, unit quaternion, ROS order)."""
    p = finite_array(name, pose).ravel()
    if p.size != 7:
        raise ValueError(f'{name} must have 7 values [x y z qx qy qz qw], got {p.size}')
    T = np.eye(4)
    try:
        T[:3, :3] = quaternion_to_rotation(p[3:])
    except ValueError as exc:
        raise ValueError(f'{name}: {exc}') from None
    T[:3, 3] = p[:3]
    return T


def rigid_transform(value: ArrayLike, name: str = 'pose',
                    tolerance: float = RIGID_TOLERANCE) -> FloatArray:
    """A rigid transform (4, 4), a new array, from a (4, 4) matrix (orthonormal rotation within
    ``tolerance``, det +1, last row ``[0 0 0 1]``) or a 7-value pose; ValueError naming ``name``
    otherwise."""
    arr = finite_array(name, value)
    if arr.shape == (7,):
        return pose_vector_to_transform(arr, name)
    if arr.shape != (4, 4):
        raise ValueError(f'{name} must be a (4, 4) transform or [x y z qx qy qz qw], '
                         f'got shape {arr.shape}')
    R = arr[:3, :3]
    if (np.max(np.abs(R.T @ R - np.eye(3))) > tolerance or np.linalg.det(R) < 0.0
            or np.any(arr[3] != (0.0, 0.0, 0.0, 1.0))):
        raise ValueError(f'{name} must be a rigid transform (orthonormal R, det +1, last row '
                         '[0 0 0 1])')
    return arr.copy()


def adjoint(P: FloatArray) -> FloatArray:
    """``Ad_P = [[R, hat(p) R], [0, R]]`` (twists ``[v; w]``) of (..., 4, 4) poses: (..., 6, 6)."""
    R = P[..., :3, :3]
    out = np.zeros(P.shape[:-2] + (6, 6))
    out[..., :3, :3] = R
    out[..., 3:, 3:] = R
    out[..., :3, 3:] = hat3(P[..., :3, 3]) @ R
    return out


def adjoint_screw_order(T: FloatArray) -> FloatArray:
    """``Ad_T = [[R, 0], [hat(p) R, R]]`` (6, 6) of a (4, 4) pose for twists ``[w; v]`` in the
    screws' order (:func:`adjoint` with both 3-blocks swapped)."""
    R = T[:3, :3]
    out = np.zeros((6, 6))
    out[:3, :3] = R
    out[3:, 3:] = R
    out[3:, :3] = hat3(T[:3, 3]) @ R
    return out


def inverse_transform(T: FloatArray) -> FloatArray:
    """``T^-1 = [[R^T, -R^T p], [0, 1]]`` of a rigid transform (4, 4), exact (no LU)."""
    R = T[:3, :3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out

"""numpy arrays <-> ``std_msgs/Float64MultiArray`` with labelled, validated layouts.

Layout convention (``std_msgs/MultiArrayLayout``, row-major): for a matrix of shape (rows, cols)
``dim[0] = (label=row_label, size=rows, stride=rows*cols)`` and
``dim[1] = (label=col_label, size=cols, stride=cols)``; a vector has one dimension
``dim[0] = (label, size=n, stride=n)``. Element ``M[i, j]`` is ``data[data_offset + i*cols + j]``.
The labels name the orderings, e.g. ``'rows: wrench [fx fy fz mx my mz]'``.

Incoming arrays are validated before use: the element count is checked against ``max_length``
before anything is converted, then against the expected length / shape, then for NaN and inf
(:func:`multiarray_to_array` and ``DEFAULT_MAX_LENGTH`` live in
:mod:`tensegrity_stiffness.nodes.messages`, which reads any message implementation; re-exported
here).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from std_msgs.msg import Float64MultiArray

from tensegrity_stiffness.geometry.validation import finite_array_of_shape
from tensegrity_stiffness.nodes.layouts import (
    CARTESIAN_STIFFNESS_COL_LABEL,
    SCREW_LABEL,
    STIFFNESS_COL_LABEL,
    STIFFNESS_ROW_LABEL,
    WRENCH_LABEL,
    matrix_dims,
    vector_dims,
)
from tensegrity_stiffness.nodes.messages import DEFAULT_MAX_LENGTH, multiarray, multiarray_to_array
from tensegrity_stiffness.ros.conversions.outputs import RCLPY_TYPES, payload

__all__ = [
    'CARTESIAN_TWIST_COL_LABEL',
    'DEFAULT_MAX_LENGTH',
    'SCREW_COL_LABEL',
    'SCREW_LABEL',
    'WRENCH_LABEL',
    'WRENCH_ROW_LABEL',
    'matrix_to_multiarray',
    'multiarray_to_array',
    'multiarray_to_matrix',
    'payload',
    'set_multiarray_data',
    'vector_to_multiarray',
]

#: Labels of the orderings (wrench rows, screw / twist columns):
#: tensegrity_stiffness.nodes.layouts.
WRENCH_ROW_LABEL = STIFFNESS_ROW_LABEL
SCREW_COL_LABEL = STIFFNESS_COL_LABEL
CARTESIAN_TWIST_COL_LABEL = CARTESIAN_STIFFNESS_COL_LABEL

FloatArray = NDArray[np.float64]


def vector_to_multiarray(values: ArrayLike, label: str = '') -> Float64MultiArray:
    """Pack a 1-D array of n values into a Float64MultiArray with one labelled dimension.

    Parameters
    ----------
    values : (n,) array_like of finite floats.
    label : name of the ordering, e.g. ``'tensions [N], string order of the config'``.

    Raises
    ------
    ValueError
        If ``values`` is not 1-D or contains NaN / inf.
    """
    arr = finite_array_of_shape('vector', values, None)
    if arr.ndim != 1:
        raise ValueError(f'vector must be 1-D, got shape {arr.shape}')
    return multiarray(vector_dims(arr.shape[0], label), arr, RCLPY_TYPES)


def matrix_to_multiarray(matrix: ArrayLike, row_label: str = WRENCH_ROW_LABEL,
                         col_label: str = SCREW_COL_LABEL) -> Float64MultiArray:
    """Pack a 2-D array (rows, cols) row-major into a Float64MultiArray with a labelled layout.

    ``dim[0]`` = (row_label, rows, rows*cols), ``dim[1]`` = (col_label, cols, cols), so that
    ``M[i, j] = data[i*cols + j]`` (ROS MultiArrayLayout convention). The default labels describe
    the screw stiffness K = dF/dxi: rows wrench [fx fy fz mx my mz], cols screw
    [wx wy wz vx vy vz].

    Raises
    ------
    ValueError
        If ``matrix`` is not 2-D or contains NaN / inf.
    """
    arr = finite_array_of_shape('matrix', matrix, None)
    if arr.ndim != 2:
        raise ValueError(f'matrix must be 2-D, got shape {arr.shape}')
    return multiarray(matrix_dims(*arr.shape, row_label, col_label), arr, RCLPY_TYPES)


def set_multiarray_data(msg: Float64MultiArray, values: ArrayLike) -> Float64MultiArray:
    """Refill the payload of a message built by :func:`matrix_to_multiarray` or
    :func:`vector_to_multiarray` (its layout is kept), for publishers that reuse one message.

    Raises
    ------
    ValueError
        If ``values`` contains NaN / inf or its size differs from the layout's element count.
    """
    arr = finite_array_of_shape('values', values, None)
    expected = msg.layout.dim[0].stride if msg.layout.dim else arr.size
    if arr.size != expected:
        raise ValueError(f'layout holds {expected} values, got {arr.size}')
    msg.data = payload(arr)
    return msg


def multiarray_to_matrix(msg: Float64MultiArray,
                         expected_shape: Sequence[int] | None = None,
                         max_length: int = DEFAULT_MAX_LENGTH) -> FloatArray:
    """Validated 2-D copy of a Float64MultiArray laid out as by :func:`matrix_to_multiarray`.

    The shape is taken from ``layout.dim`` (two dimensions, sizes and strides consistent with a
    dense row-major matrix) or, if the layout is empty, from ``expected_shape``. When both are
    present they must agree.

    Raises
    ------
    ValueError
        On an inconsistent layout, a shape other than ``expected_shape``, or any error of
        :func:`multiarray_to_array`.
    """
    dims = list(msg.layout.dim)
    if dims:
        if len(dims) != 2:
            raise ValueError(f'layout must have 2 dimensions, got {len(dims)}')
        rows, cols = int(dims[0].size), int(dims[1].size)
        if int(dims[1].stride) != cols or int(dims[0].stride) != rows * cols:
            raise ValueError(
                f'layout strides ({dims[0].stride}, {dims[1].stride}) are not those of a dense '
                f'row-major {rows}x{cols} matrix ({rows * cols}, {cols})')
        if expected_shape is not None and (rows, cols) != tuple(expected_shape):
            raise ValueError(f'expected shape {tuple(expected_shape)}, got ({rows}, {cols})')
    elif expected_shape is not None:
        rows, cols = (int(s) for s in expected_shape)
    else:
        raise ValueError('layout has no dimensions and no expected_shape was given')
    flat = multiarray_to_array(msg, expected_length=rows * cols, max_length=max_length)
    return flat.reshape(rows, cols)

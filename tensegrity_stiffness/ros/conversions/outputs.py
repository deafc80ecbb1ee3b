"""rclpy's message classes for :mod:`tensegrity_stiffness.nodes.messages` (:data:`RCLPY_TYPES`),
which
builds the nodes' output messages from the layouts of :mod:`tensegrity_stiffness.nodes.layouts` and
refills them per input (the bag command does the same with rosbags' types)."""

from __future__ import annotations

import array
from collections.abc import Mapping
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import (
    Point,
    Pose,
    PoseStamped,
    PoseWithCovariance,
    PoseWithCovarianceStamped,
    Quaternion,
    Vector3,
    Wrench,
    WrenchStamped,
)
from numpy.typing import NDArray
from std_msgs.msg import Float64MultiArray, Header, MultiArrayDimension, MultiArrayLayout

from tensegrity_stiffness.msg import StampedMatrix
from tensegrity_stiffness.nodes.layouts import OutputLayout
from tensegrity_stiffness.nodes.messages import (
    MESSAGE_CLASS_NAMES,
    MessageTypes,
    fill_outputs,
    payload_writer,
    write_wrench_stamped,
)

__all__ = ['RCLPY_TYPES', 'fill_outputs', 'output_topics', 'payload', 'write_payload',
           'write_wrench_stamped']


def payload(arr: NDArray[np.float64]) -> array.array:
    """Row-major float64 payload for ``Float64MultiArray.data`` (one memcpy, no Python loop; no
    checks: for arrays already checked finite and of the layout's size)."""
    data = array.array('d')
    data.frombytes(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
    return data


#: rclpy's classes of the output messages, ``float64[]`` fields as ``array.array('d')``.
RCLPY_TYPES = MessageTypes(
    classes=dict(zip(MESSAGE_CLASS_NAMES, (
        Time, Header, MultiArrayDimension, MultiArrayLayout, Float64MultiArray, Vector3, Wrench,
        WrenchStamped, Point, Quaternion, Pose, PoseStamped, StampedMatrix, PoseWithCovariance,
        PoseWithCovarianceStamped), strict=True)),
    payload=payload)

#: Writes an array into a ``Float64MultiArray`` of rclpy (:func:`fill_outputs`' writer form).
write_payload = payload_writer(RCLPY_TYPES)


def output_topics(layouts: Mapping[str, OutputLayout]) -> tuple[tuple[Any, str], ...]:
    """``(rclpy message class, '~/<name>')`` of a node's outputs, in their order (the node's
    ``OUTPUT_TOPICS`` from :mod:`tensegrity_stiffness.nodes.layouts`)."""
    return tuple((RCLPY_TYPES.classes[layout.msgtype], f'~/{name}')
                 for name, layout in layouts.items())

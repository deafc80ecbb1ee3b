"""The nodes' output messages with rclpy's message classes: :data:`RCLPY_TYPES` for
:mod:`tensegrity_stiffness.messages`, which builds them from the layouts of
:mod:`tensegrity_stiffness.layouts` and refills them per input (the bag command does the same
with rosbags' types)."""

from __future__ import annotations

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Vector3, Wrench, WrenchStamped
from std_msgs.msg import Float64MultiArray, Header, MultiArrayDimension, MultiArrayLayout

from msg_tools.arrays import payload
from tensegrity_stiffness.messages import MESSAGE_CLASS_NAMES, MessageTypes

__all__ = ['RCLPY_TYPES']

#: rclpy's classes of the output messages, ``float64[]`` fields as ``array.array('d')``.
RCLPY_TYPES = MessageTypes(
    classes=dict(zip(MESSAGE_CLASS_NAMES, (
        Time, Header, MultiArrayDimension, MultiArrayLayout, Float64MultiArray, Vector3, Wrench,
        WrenchStamped, Point, Quaternion, Pose, PoseStamped), strict=True)),
    payload=payload)

"""The nodes' frames on ``/tf`` and ``/tf_static`` (``tf.enabled``, default true), through public
rclpy API (no tf2_ros), with tf2's QoS: ``/tf`` reliable, keep-last 100, volatile (tf2_ros'
``DynamicBroadcasterQoS``); ``/tf_static`` reliable, keep-last 1, transient local
(``StaticBroadcasterQoS``: a late subscriber gets the node's fixed frames). Which frames:
:mod:`tensegrity_stiffness.nodes.frames`.

Only when ``tf2_msgs`` is importable (a stock ROS install; it is not on PyPI): otherwise the
broadcaster creates nothing and the node runs as before (its ready line says so). The mixins give
a :class:`~.node_base.StreamingNode` its frames: :class:`JointFrames` (link 1 -> link 2) and
:class:`SpineFrames` (base -> every link, link N -> tool).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from geometry_msgs.msg import TransformStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from tensegrity_stiffness.nodes.frames import (
    FrameTransform,
    joint_frame_transforms,
    spine_frame_transforms,
    spine_tool_transform,
)
from tensegrity_stiffness.nodes.messages import pose_values
from tensegrity_stiffness.ros.runtime.topics import create_output_publisher

TF_TOPIC = '/tf'
TF_STATIC_TOPIC = '/tf_static'
#: tf2_ros' DynamicBroadcasterQoS and StaticBroadcasterQoS.
TF_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
TF_STATIC_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)


def tf_message_type() -> Any:
    """``tf2_msgs/msg/TFMessage``, or None when ``tf2_msgs`` is not installed."""
    try:
        from tf2_msgs.msg import TFMessage
    except ImportError:
        return None
    return TFMessage


def transform_stamped(frame: FrameTransform, stamp: Any) -> TransformStamped:
    """The ``geometry_msgs/TransformStamped`` of ``frame`` (parent in ``header.frame_id``);
    ValueError when its transform is not a finite rigid transform."""
    (px, py, pz), (qx, qy, qz, qw) = pose_values(frame.transform)
    msg = TransformStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = frame.parent
    msg.child_frame_id = frame.child
    translation, rotation = msg.transform.translation, msg.transform.rotation
    translation.x, translation.y, translation.z = px, py, pz
    rotation.x, rotation.y, rotation.z, rotation.w = qx, qy, qz, qw
    return msg


class FrameBroadcaster:
    """The ``/tf`` and ``/tf_static`` publishers of a node (none without ``tf2_msgs``)."""

    def __init__(self, node: Node) -> None:
        self._type = tf_message_type()
        self._dynamic = self._static = None
        if self._type is not None:
            self._dynamic = create_output_publisher(node, self._type, TF_TOPIC, TF_QOS)
            self._static = create_output_publisher(node, self._type, TF_STATIC_TOPIC,
                                                   TF_STATIC_QOS)

    @property
    def status(self) -> str:
        """For the ready line: where the frames go."""
        return 'frames on /tf' if self._type is not None else 'no /tf (tf2_msgs not installed)'

    def message(self, frames: Iterable[FrameTransform], stamp: Any) -> Any:
        """The ``TFMessage`` of ``frames`` at ``stamp`` for :meth:`publish`; None while nobody
        subscribes to ``/tf`` (or without tf2_msgs). ValueError when a transform is not a finite
        rigid transform (built before anything of the input is published)."""
        publisher = self._dynamic
        if publisher is None or publisher.get_subscription_count() == 0:
            return None
        return self._type(transforms=[transform_stamped(f, stamp) for f in frames])

    def publish(self, message: Any) -> None:
        """A :meth:`message` on ``/tf``."""
        self._dynamic.publish(message)

    def send(self, frames: Iterable[FrameTransform], stamp: Any) -> None:
        """``frames`` on ``/tf`` at ``stamp``, while someone subscribes."""
        message = self.message(frames, stamp)
        if message is not None:
            self.publish(message)

    def send_static(self, frames: Iterable[FrameTransform], stamp: Any) -> None:
        """``frames`` on ``/tf_static`` (latched: all of the node's fixed frames in one message,
        replacing the last one); nothing when ``frames`` is empty."""
        transforms = [transform_stamped(f, stamp) for f in frames]
        if self._static is not None and transforms:
            self._static.publish(self._type(transforms=transforms))


class JointFrames:
    """The frames of a joint node (settings with ``link1_frame`` and ``link2_frame``, outputs
    whose ``state`` is a :class:`~tensegrity_stiffness.mechanics.joint.JointState`)."""

    def _frame_transforms(self, settings: Any, state: Any) -> tuple[FrameTransform, ...]:
        return joint_frame_transforms(settings.link1_frame, settings.link2_frame,
                                      state.transform)

    def _static_frame_transforms(self, settings: Any) -> tuple[FrameTransform, ...]:
        return ()


class SpineFrames:
    """The frames of a spine node (settings with ``chain``, ``base_frame`` and ``tool_frame``,
    outputs whose ``state`` is a :class:`~tensegrity_stiffness.mechanics.chain.ChainState`)."""

    def _frame_transforms(self, settings: Any, state: Any) -> tuple[FrameTransform, ...]:
        return spine_frame_transforms(settings.base_frame, state.link_transforms)

    def _static_frame_transforms(self, settings: Any) -> tuple[FrameTransform, ...]:
        return (spine_tool_transform(settings.base_frame, settings.chain.n_joints,
                                     settings.tool_frame, settings.chain.tool),)

"""QoS profiles and publishers shared by the package's nodes."""

from __future__ import annotations

from typing import Any

from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


def input_qos(depth: int, reliability: str) -> QoSProfile:
    """Keep-last ``depth``, volatile, reliable or best effort: the streamed inputs."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=(ReliabilityPolicy.BEST_EFFORT if reliability == 'best_effort'
                                   else ReliabilityPolicy.RELIABLE),
                      durability=DurabilityPolicy.VOLATILE)


#: State inputs (rest lengths): reliable + transient local, depth 1, so that a restarted node
#: gets the latest value from a latched publisher.
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)


def create_output_publisher(node: Node, msg_type: Any, topic: str, qos: QoSProfile | int) -> Any:
    """A publisher without rclpy's default QoS-event handlers: each would be one more waitable
    the executor rebuilds its wait set with before every callback (an incompatible subscriber is
    still reported on its own side)."""
    return node.create_publisher(msg_type, topic, qos, event_callbacks=PublisherEventCallbacks(
        use_default_callbacks=False))


def output_qos(depth: int) -> QoSProfile:
    """Reliable, keep-last ``depth``, volatile: the per-input outputs."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)

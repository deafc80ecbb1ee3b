"""The messages of the joint node's five per-input outputs (``~/wrench``, ``~/stiffness``,
``~/cartesian_stiffness``, ``~/string_tensions``, ``~/stiffness_interpretation``) and its markers.

One preallocated message per topic, its layout labelled once from
:func:`tensegrity_stiffness.nodes.layouts.joint_output_layouts`; per input only the data and the
header
are refilled, after one finite check of every output (:func:`processing.require_finite`:
ValueError naming the output, and nothing is published). The messages are
:class:`tensegrity_stiffness.nodes.messages.JointOutputMessages` with rclpy's classes.
"""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from visualization_msgs.msg import MarkerArray

from tensegrity_stiffness.mechanics.joint import JointModel, JointState
from tensegrity_stiffness.nodes import messages
from tensegrity_stiffness.ros.conversions.markers import marker_array
from tensegrity_stiffness.ros.conversions.outputs import RCLPY_TYPES

__all__ = ['JointOutputMessages', 'joint_markers']


class JointOutputMessages(messages.JointOutputMessages):
    """The five output messages of one joint (rclpy), refilled per input by :meth:`fill`."""

    def __init__(self, string_names: tuple[str, ...]) -> None:
        super().__init__(string_names, RCLPY_TYPES)


def joint_markers(model: JointModel, state: JointState, frame_id: str, stamp: Time
                  ) -> MarkerArray:
    """:func:`marker_array` of one joint configuration: tensions coloured up to the saturation
    tension ``k (lmax - l0)`` of the strongest string (up to the largest tension without a
    limit)."""
    saturation = model.k * model.max_stretch
    top = float(np.max(saturation)) if np.all(np.isfinite(saturation)) else None
    return marker_array(model.link1_nodes, model.link2_nodes_in_link1(state.transform),
                        model.connections, state.tensions, state.slack, frame_id, stamp,
                        max_tension=top)

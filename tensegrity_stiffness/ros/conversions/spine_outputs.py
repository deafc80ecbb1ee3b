"""The messages of the spine node's per-input outputs (``~/joint_wrenches``,
``~/joint_stiffness``, ``~/joint_cartesian_stiffness``, ``~/tip_pose``, ``~/tip_wrench``,
``~/tip_stiffness``, ``~/tip_stiffness_base``) and its markers.

One preallocated message per topic, its layout labelled once from
:func:`tensegrity_stiffness.nodes.layouts.spine_output_layouts`; per input only the data and the
headers are refilled, after one finite check of every output
(:func:`tensegrity_stiffness.nodes.spine_node.require_finite`: ValueError naming the output,
and nothing is published). The messages are
:class:`tensegrity_stiffness.nodes.messages.SpineOutputMessages` with rclpy's classes.
"""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from visualization_msgs.msg import MarkerArray

from tensegrity_stiffness.mechanics.chain import ChainState, JointChain
from tensegrity_stiffness.nodes import messages
from tensegrity_stiffness.ros.conversions.markers import marker_array
from tensegrity_stiffness.ros.conversions.outputs import RCLPY_TYPES

__all__ = ['SpineOutputMessages', 'spine_markers']


class SpineOutputMessages(messages.SpineOutputMessages):
    """The seven output messages of a spine of ``n_joints`` (rclpy), refilled per input by
    :meth:`fill`."""

    def __init__(self, n_joints: int, tool_frame: str = '') -> None:
        super().__init__(n_joints, RCLPY_TYPES, tool_frame)


def _in_base(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ pose[:3, :3].T + pose[:3, 3]


def spine_markers(chain: JointChain, state: ChainState, frame_id: str, stamp: Time
                  ) -> MarkerArray:
    """The markers of :func:`marker_array` for every joint, in the base frame (namespaces
    ``joint_<i>/...``): tensions coloured up to the largest saturation tension ``k (lmax - l0)``
    of all strings (up to the largest tension without a limit)."""
    saturation = np.concatenate([np.ravel(m.k * m.max_stretch) for m in chain.joints])
    top = float(np.max(saturation)) if np.all(np.isfinite(saturation)) else None
    if top is None:
        taut = np.concatenate([np.asarray(t)[~np.asarray(s)] for t, s in
                               zip(state.tensions, state.slack, strict=True)])
        top = float(taut.max()) if taut.size and taut.max() > 0.0 else 1.0
    markers = []
    for i, model in enumerate(chain.joints):
        joint = marker_array(_in_base(state.joint_frames[i], model.link1_nodes),
                             _in_base(state.link_transforms[i], model.link2_nodes),
                             model.connections, state.tensions[i], state.slack[i], frame_id,
                             stamp, max_tension=top)
        for marker in joint.markers:
            marker.ns = f'joint_{i + 1}/{marker.ns}'
        markers += joint.markers
    return MarkerArray(markers=markers)

"""The messages of the spine node's per-input outputs (``~/joint_wrenches``,
``~/joint_stiffness``, ``~/joint_cartesian_stiffness``, ``~/tip_pose``, ``~/tip_wrench``,
``~/tip_stiffness``, ``~/tip_stiffness_base``) and its markers.

One preallocated message per topic, its layout labelled once from
:mod:`tensegrity_stiffness.layouts`; per input only the data and the headers are refilled, after
one finite check of every output (:func:`spine_processing.require_finite`: ValueError naming the
output, and nothing is published).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, WrenchStamped
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout
from visualization_msgs.msg import MarkerArray

from msg_tools.arrays import matrix_to_multiarray
from msg_tools.markers import marker_array
from msg_tools.outputs import (
    fill_outputs,
    write_payload,
    write_pose_stamped,
    write_wrench_stamped,
)
from tensegrity_stiffness.chain import ChainState, JointChain
from tensegrity_stiffness.layouts import (
    CARTESIAN_STIFFNESS_COL_LABEL,
    JOINTS_LABEL,
    STIFFNESS_COL_LABEL,
    STIFFNESS_ROW_LABEL,
    TIP_STIFFNESS_LABELS,
    WRENCH_LABEL,
    matrix_dims,
    stacked_matrix_dims,
)
from tensegrity_stiffness.spine_processing import SpineOutputs, output_arrays, require_finite

__all__ = ['SpineOutputMessages', 'spine_markers']


def _multiarray(dims: list[tuple[str, int, int]]) -> Float64MultiArray:
    """A zero-filled Float64MultiArray with the layout ``dims`` ((label, size, stride) each)."""
    layout = MultiArrayLayout(dim=[MultiArrayDimension(label=label, size=size, stride=stride)
                                   for label, size, stride in dims], data_offset=0)
    return Float64MultiArray(layout=layout, data=[0.0] * dims[0][2])


class SpineOutputMessages:
    """The seven output messages of a spine of ``n_joints``, refilled per input by
    :meth:`fill`."""

    def __init__(self, n_joints: int) -> None:
        self.n_joints = n_joints
        self.joint_wrenches = _multiarray(matrix_dims(n_joints, 6, JOINTS_LABEL, WRENCH_LABEL))
        self.joint_stiffness = _multiarray(stacked_matrix_dims(
            n_joints, 6, 6, JOINTS_LABEL, STIFFNESS_ROW_LABEL, STIFFNESS_COL_LABEL))
        self.joint_cartesian_stiffness = _multiarray(stacked_matrix_dims(
            n_joints, 6, 6, JOINTS_LABEL, STIFFNESS_ROW_LABEL, CARTESIAN_STIFFNESS_COL_LABEL))
        self.tip_pose = PoseStamped()
        self.tip_wrench = WrenchStamped()
        self.tip_stiffness = matrix_to_multiarray(np.zeros((6, 6)),
                                                  *TIP_STIFFNESS_LABELS['tool'])
        self.tip_stiffness_base = matrix_to_multiarray(np.zeros((6, 6)),
                                                       *TIP_STIFFNESS_LABELS['base'])

    #: The writer of each message, in :meth:`messages` order.
    WRITERS = (write_payload, write_payload, write_payload, write_pose_stamped,
               write_wrench_stamped, write_payload, write_payload)

    def fill(self, outputs: SpineOutputs, stamp: Time, base_frame: str,
             wanted: tuple[bool, ...] | None = None) -> None:
        """Set the messages from ``outputs`` (those flagged in ``wanted``, in :meth:`messages`
        order; default all); ValueError if any output is not finite (then none is set)."""
        require_finite(outputs)
        fill_outputs(self.messages(), output_arrays(outputs), self.WRITERS, stamp, base_frame,
                     wanted)

    def messages(self) -> tuple[Any, ...]:
        """The messages in topic order: joint_wrenches, joint_stiffness,
        joint_cartesian_stiffness, tip_pose, tip_wrench, tip_stiffness, tip_stiffness_base."""
        return (self.joint_wrenches, self.joint_stiffness, self.joint_cartesian_stiffness,
                self.tip_pose, self.tip_wrench, self.tip_stiffness, self.tip_stiffness_base)


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

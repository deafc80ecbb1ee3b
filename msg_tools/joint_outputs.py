"""The messages of the joint node's five per-input outputs (``~/wrench``, ``~/stiffness``,
``~/cartesian_stiffness``, ``~/string_tensions``, ``~/stiffness_interpretation``) and its markers.

One preallocated message per topic, its layout labelled once from
:mod:`tensegrity_stiffness.layouts`; per input only the data and the header are refilled, after
one finite check of every output (:func:`processing.require_finite`: ValueError naming the
output, and nothing is published).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import WrenchStamped
from visualization_msgs.msg import MarkerArray

from msg_tools.arrays import matrix_to_multiarray, vector_to_multiarray
from msg_tools.markers import marker_array
from msg_tools.outputs import fill_outputs, write_payload, write_wrench_stamped
from tensegrity_stiffness.joint import JointModel, JointState
from tensegrity_stiffness.layouts import (
    CARTESIAN_STIFFNESS_COL_LABEL,
    INTERPRETATION_LABEL,
    INTERPRETATION_SIZE,
    STIFFNESS_COL_LABEL,
    STIFFNESS_ROW_LABEL,
    tensions_label,
)
from tensegrity_stiffness.processing import JointOutputs, output_arrays, require_finite

__all__ = ['JointOutputMessages', 'joint_markers']


class JointOutputMessages:
    """The five output messages of one joint, refilled per input by :meth:`fill`."""

    def __init__(self, string_names: tuple[str, ...]) -> None:
        self.string_names = tuple(string_names)
        self.wrench = WrenchStamped()
        self.stiffness = matrix_to_multiarray(np.zeros((6, 6)), STIFFNESS_ROW_LABEL,
                                              STIFFNESS_COL_LABEL)
        self.cartesian_stiffness = matrix_to_multiarray(
            np.zeros((6, 6)), STIFFNESS_ROW_LABEL, CARTESIAN_STIFFNESS_COL_LABEL)
        self.tensions = vector_to_multiarray(np.zeros(len(self.string_names)),
                                             tensions_label(self.string_names))
        self.interpretation = vector_to_multiarray(np.zeros(INTERPRETATION_SIZE),
                                                   INTERPRETATION_LABEL)

    #: The writer of each message, in :meth:`messages` order.
    WRITERS = (write_wrench_stamped, write_payload, write_payload, write_payload, write_payload)

    def fill(self, outputs: JointOutputs, stamp: Time, frame_id: str,
             wanted: tuple[bool, ...] | None = None) -> None:
        """Set the messages from ``outputs`` (those flagged in ``wanted``, in :meth:`messages`
        order; default all); ValueError if any output is not finite (then none is set)."""
        require_finite(outputs)
        fill_outputs(self.messages(), output_arrays(outputs), self.WRITERS, stamp, frame_id,
                     wanted)

    def messages(self) -> tuple[Any, ...]:
        """The messages in topic order: wrench, stiffness, cartesian_stiffness, tensions,
        interpretation."""
        return (self.wrench, self.stiffness, self.cartesian_stiffness, self.tensions,
                self.interpretation)


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
